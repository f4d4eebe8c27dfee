//! The imposed triangle the drive tests run the machine with (`mod imposed;` in each).
use hal_sim::plant::Motion;
use hal_sim::Scenario;

/// An imposed triangle at `v` m/s (amplitude 0.4 m: a quarter cycle lasts 0.4/v s, longer
/// than the calibration and the alignment at every speed tested), 306 Ω, 10 s, no record
/// channels.
pub fn triangle(v: f64) -> Scenario {
    let a = 0.4;
    let mut sc = Scenario::imposed(
        Motion::Triangle {
            amplitude_m: a,
            freq_hz: v / (4.0 * a),
        },
        306.0,
        10.0,
    );
    sc.record.channels.clear();
    sc
}

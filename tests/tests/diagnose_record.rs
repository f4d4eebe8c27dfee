//! Record reader: bad files get a clear error naming the line.

use hal_sim::diagnose::parse_csv;

fn good(n: usize) -> String {
    let mut s = String::from("# lead_m_per_rev = 0.016\nt_s,x_m,f_N\n");
    for i in 0..n {
        let t = i as f64 * 1e-3;
        s.push_str(&format!(
            "{t},{},{}\n",
            0.01 * (t * 6.0).sin(),
            10.0 * (t * 6.0).cos()
        ));
    }
    s
}

#[test]
fn good_record_parses_with_metadata_and_derivatives() {
    let r = parse_csv(&good(2000), None).unwrap();
    assert_eq!(r.len(), 2000);
    assert_eq!(r.meta["lead_m_per_rev"], 0.016);
    // v = 0.06 cos(6t): the zero-phase derivative at mid-record matches within 1 % of the peak
    // (50 Hz cutoff leaves a 1 Hz signal untouched; the error is the central-difference
    // truncation, O((w dt)^2)).
    let i = 1000;
    let t = r.t[i];
    assert!((r.v[i] - 0.06 * (6.0 * t).cos()).abs() < 6e-4, "{}", r.v[i]);
}

#[test]
fn bad_records_name_the_line() {
    let e = parse_csv("t_s,x_m\n0,1\n", None).unwrap_err();
    assert_eq!(e.line, Some(1));
    assert!(e.msg.contains("f_N"), "{e}");

    let mut s = good(10);
    s = s.replacen("0.002,", "0.0005,", 1); // line 5: time goes back
    let e = parse_csv(&s, None).unwrap_err();
    assert_eq!(e.line, Some(5), "{e}");
    assert!(e.msg.contains("time"), "{e}");

    let s = good(10)
        .replacen("\n0.003,", "\n0.003,NaN,", 1)
        .replacen("NaN,0", "NaN", 1);
    let e = parse_csv(&s, None).unwrap_err();
    assert_eq!(e.line, Some(6), "{e}");

    let e = parse_csv("t_s,x_m,f_N\n0,0,0\n", None).unwrap_err();
    assert!(e.msg.contains("at least 3"), "{e}");

    // displacement in millimetres
    let s = "t_s,x_m,f_N\n0,0,1\n0.001,20,1\n0.002,40,1\n";
    let e = parse_csv(s, None).unwrap_err();
    assert_eq!(e.line, Some(3), "{e}");
    assert!(e.msg.contains("metres"), "{e}");

    // time in milliseconds
    let s = "t_s,x_m,f_N\n0,0,1\n2,0.001,1\n4,0.002,1\n";
    let e = parse_csv(s, None).unwrap_err();
    assert!(e.msg.contains("seconds"), "{e}");

    // wrong field count
    let e = parse_csv("t_s,x_m,f_N\n0,0,1\n0.001,0\n", None).unwrap_err();
    assert_eq!(e.line, Some(3), "{e}");
}

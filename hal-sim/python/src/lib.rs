//! `regensim._regensim`: the PyO3 layer of the `regensim` Python package. Every entry point
//! calls the code the `regen` command line runs (`hal_sim::scenario`, `hal_sim::cli::run::
//! simulate`, `hal_sim::cli::sweep::set_param`, `hal_sim::analytic`, `hal_sim::lqg`,
//! `hal_sim::diagnose`); nothing here computes physics. The Python side (`regensim/*.py`) adds
//! the result classes, the Dask/process-pool `study` and the docstrings the stubs repeat.

use hal_sim::analytic::{self, DampingFormula, DesignCase};
use hal_sim::plant::{Drive, Excitation, Machine, Screw};
use hal_sim::sim::Energy;
use hal_sim::Scenario;
use numpy::IntoPyArray;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use pyo3::IntoPyObjectExt;

create_exception!(
    _regensim,
    RegenError,
    PyValueError,
    "Refused input: the message is the `regen` command line's (key, value, allowed range)."
);

fn err(msg: impl Into<String>) -> PyErr {
    RegenError::new_err(msg.into())
}

/// A scenario (the TOML file `regen run` reads), validated on every change.
#[pyclass(module = "regensim._regensim", name = "Scenario", eq)]
#[derive(Clone, PartialEq)]
struct PyScenario {
    inner: Scenario,
}

fn toml_to_py(py: Python<'_>, v: &toml::Value) -> PyResult<Py<PyAny>> {
    Ok(match v {
        toml::Value::String(s) => s.into_py_any(py)?,
        toml::Value::Integer(i) => i.into_py_any(py)?,
        toml::Value::Float(f) => f.into_py_any(py)?,
        toml::Value::Boolean(b) => b.into_py_any(py)?,
        toml::Value::Datetime(d) => d.to_string().into_py_any(py)?,
        toml::Value::Array(a) => {
            let items = a
                .iter()
                .map(|x| toml_to_py(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any().unbind()
        }
        toml::Value::Table(t) => {
            let d = PyDict::new(py);
            for (k, x) in t {
                d.set_item(k, toml_to_py(py, x)?)?;
            }
            d.into_any().unbind()
        }
    })
}

/// A Python value as TOML; `like` (the value it replaces) decides int → float.
fn py_to_toml(
    key: &str,
    o: &Bound<'_, PyAny>,
    like: Option<&toml::Value>,
) -> PyResult<toml::Value> {
    if o.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(o.extract()?));
    }
    if o.is_instance_of::<PyInt>() {
        if let Some(toml::Value::Float(_)) | None = like {
            if like.is_some() {
                return Ok(toml::Value::Float(o.extract::<f64>()?));
            }
        }
        return match o.extract::<i64>() {
            Ok(i) => Ok(toml::Value::Integer(i)),
            Err(_) => Err(err(format!("{key} = {o}: integer out of range"))),
        };
    }
    if o.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(o.extract()?));
    }
    if o.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(o.extract()?));
    }
    if let Ok(d) = o.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, v) in d.iter() {
            let k: String = k.extract()?;
            let prev = match like {
                Some(toml::Value::Table(p)) => p.get(&k),
                _ => None,
            };
            t.insert(k.clone(), py_to_toml(&format!("{key}.{k}"), &v, prev)?);
        }
        return Ok(toml::Value::Table(t));
    }
    if o.is_instance_of::<PyList>() || o.is_instance_of::<PyTuple>() || o.hasattr("tolist")? {
        let seq = if o.hasattr("tolist")? {
            o.call_method0("tolist")?
        } else {
            o.clone()
        };
        let prev = match like {
            Some(toml::Value::Array(a)) => a.first(),
            _ => None,
        };
        let mut a = Vec::new();
        for x in seq.try_iter()? {
            a.push(py_to_toml(key, &x?, prev)?);
        }
        return Ok(toml::Value::Array(a));
    }
    Err(err(format!(
        "{key}: a {} cannot be a scenario value (number, bool, string, list or dict)",
        o.get_type().name()?
    )))
}

impl PyScenario {
    fn value(&self) -> PyResult<toml::Value> {
        toml::Value::try_from(&self.inner).map_err(|e| err(e.to_string()))
    }

    /// The dotted scenario path a key means: the sweep's names are where `set_param` puts
    /// them, a registry name (console `set`) is `law.set.NAME`.
    fn path(key: &str) -> String {
        let sweep = match key {
            "r_load_ohm" => Some("law.r_load_ohm"),
            "a0_m_s2" => Some("drive.excitation.a0_m_s2"),
            "freq_hz" => Some("drive.excitation.freq_hz"),
            "ke_v_s_per_rad" => Some("machine.ke_v_s_per_rad"),
            "current_bw_hz" => Some("firmware.current_bw_hz"),
            _ => None,
        };
        if let Some(p) = sweep {
            p.to_string()
        } else if !key.contains('.') && regen_fw::params::find(key).is_some() {
            format!("law.set.{key}")
        } else {
            key.to_string()
        }
    }
}

fn lookup<'a>(v: &'a toml::Value, path: &str) -> Option<&'a toml::Value> {
    path.split('.').try_fold(v, |v, k| v.as_table()?.get(k))
}

#[pymethods]
impl PyScenario {
    /// Parse scenario TOML text (errors name the key and line).
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<Self> {
        Scenario::from_toml(text)
            .map(|inner| PyScenario { inner })
            .map_err(err)
    }

    /// Read a scenario file, as `regen run FILE` does.
    #[staticmethod]
    fn from_file(path: std::path::PathBuf) -> PyResult<Self> {
        Scenario::from_file(&path)
            .map(|inner| PyScenario { inner })
            .map_err(err)
    }

    /// The reference TMD (400 kg, 2 s, base sine 1 m/s² at 0.5 Hz, 12 s, averages after 8 s)
    /// with an emulated resistor of `r_load_ohm` Ω per phase.
    #[staticmethod]
    #[pyo3(signature = (r_load_ohm = 306.0))]
    fn tmd(r_load_ohm: f64) -> PyResult<Self> {
        let inner = Scenario::tmd(r_load_ohm);
        inner.config().map_err(err)?;
        Ok(PyScenario { inner })
    }

    /// The scenario as TOML text (`Scenario.from_toml(s.to_toml()) == s`).
    fn to_toml(&self) -> PyResult<String> {
        toml::to_string(&self.inner).map_err(|e| err(e.to_string()))
    }

    /// The scenario as nested dicts (the TOML's tables).
    fn to_dict(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        toml_to_py(py, &self.value()?)
    }

    /// Value of a key: a dotted scenario path (`law.r_load_ohm`, `drive.excitation.seed`) or a
    /// firmware registry name (`trk_period_s`, read from `[law.set]`; the configuration's
    /// value when the scenario does not set it).
    fn get(&self, py: Python<'_>, key: &str) -> PyResult<Py<PyAny>> {
        let v = self.value()?;
        if let Some(x) = lookup(&v, &Self::path(key)) {
            return toml_to_py(py, x);
        }
        if let Some(p) = regen_fw::params::find(key) {
            let c = self.inner.config().map_err(err)?;
            return (p.get(&c) as f64).into_py_any(py);
        }
        if let Some(x) = lookup(&v, key) {
            return toml_to_py(py, x);
        }
        Err(err(format!("{key}: no such scenario key or parameter")))
    }

    /// Set a key and validate the whole scenario as `regen` does; on refusal raise
    /// `RegenError` with the command line's message and leave the scenario unchanged.
    /// Keys: `regen sweep --param` names (`r_load_ohm`, `a0_m_s2`, `freq_hz`,
    /// `ke_v_s_per_rad`, `current_bw_hz`: exactly the sweep's setter), firmware registry
    /// names (into `[law.set]`), or dotted scenario paths (any table or value).
    fn set(&mut self, key: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        const SWEEP: [&str; 5] = [
            "r_load_ohm",
            "a0_m_s2",
            "freq_hz",
            "ke_v_s_per_rad",
            "current_bw_hz",
        ];
        let next = if SWEEP.contains(&key) {
            let v: f64 = value
                .extract()
                .map_err(|_| err(format!("{key} = {value}: a number is expected")))?;
            let mut s = self.inner.clone();
            hal_sim::cli::sweep::set_param(&mut s, key, v).map_err(err)?;
            s
        } else {
            let mut root = self.value()?;
            let path = Self::path(key);
            let parts: Vec<&str> = path.split('.').collect();
            let (last, tables) = parts.split_last().expect("split yields one part");
            let mut t = root
                .as_table_mut()
                .ok_or_else(|| err("scenario is not a table"))?;
            for p in tables {
                t = t
                    .entry(p.to_string())
                    .or_insert_with(|| toml::Value::Table(Default::default()))
                    .as_table_mut()
                    .ok_or_else(|| err(format!("{key}: `{p}` is a value, not a table")))?;
            }
            let new = py_to_toml(key, value, t.get(*last))?;
            t.insert(last.to_string(), new);
            let text = toml::to_string(&root).map_err(|e| err(format!("{key}: {e}")))?;
            Scenario::from_toml(&text).map_err(|e| err(format!("{key} = {value}: {e}")))?
        };
        // The checks `regen run` and `regen sweep` make before running.
        let text = toml::to_string(&next).map_err(|e| err(format!("{key}: {e}")))?;
        let checked = Scenario::from_toml(&text).map_err(err)?;
        checked.config().map_err(err)?;
        self.inner = next;
        Ok(())
    }

    /// A copy.
    fn copy(&self) -> Self {
        self.clone()
    }

    #[getter]
    fn name(&self) -> String {
        self.inner.name.clone()
    }

    /// Simulated time, s.
    #[getter]
    fn duration_s(&self) -> f64 {
        self.inner.duration_s
    }

    /// Time after which averages are taken, s.
    #[getter]
    fn settle_s(&self) -> f64 {
        self.inner.settle_s
    }

    fn __repr__(&self) -> String {
        format!(
            "Scenario(name={:?}, duration_s={}, law={:?})",
            self.inner.name, self.inner.duration_s, self.inner.law.kind
        )
    }

    /// Pickles as its TOML.
    fn __reduce__(&self, py: Python<'_>) -> PyResult<(Py<PyAny>, (String,))> {
        let f = py.get_type::<PyScenario>().getattr("from_toml")?.unbind();
        Ok((f, (self.to_toml()?,)))
    }
}

/// The ledger's fields, J, in `Energy`'s order (as `regen run` prints it).
fn energy_fields(e: &Energy) -> Vec<(&'static str, f64)> {
    vec![
        ("external_work", e.external_work),
        ("device_work", e.device_work),
        ("friction_loss", e.friction_loss),
        ("viscous_b_loss", e.viscous_b_loss),
        ("screw_loss", e.screw_loss),
        ("electromechanical", e.electromechanical),
        ("copper_loss", e.copper_loss),
        ("to_inverter", e.to_inverter),
        ("switching_loss", e.switching_loss),
        ("conduction_loss", e.conduction_loss),
        ("logic_loss", e.logic_loss),
        ("brake", e.brake),
        ("source_r_loss", e.source_r_loss),
        ("sink", e.sink),
        ("structure_damping", e.structure_damping),
        ("stored_start", e.stored_start),
        ("stored_now", e.stored_now),
    ]
}

fn energy_dict<'py>(py: Python<'py>, e: &Energy) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in energy_fields(e) {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// One closed-loop run (`regen run`'s loop, `hal_sim::cli::run::simulate`) with the GIL
/// released. Returns a dict: `channels` (name → float64 array), `energy` and
/// `energy_at_settle` (J), `fault`, `faults_text`, `valid` and `why` (the run's verdict,
/// `hal_sim::summary::verdict`: why it is not a result, or None), `steps`, `settle_step`,
/// `period_s`, `wall_s`, `summary`.
#[pyfunction]
#[pyo3(signature = (scenario, record = true))]
fn simulate(py: Python<'_>, scenario: &PyScenario, record: bool) -> PyResult<Py<PyAny>> {
    let mut sc = scenario.inner.clone();
    if !record {
        sc.record.channels.clear();
    }
    let o = py
        .detach(|| hal_sim::cli::run::simulate(&sc, &mut |_| {}))
        .map_err(err)?;
    let d = PyDict::new(py);
    let ch = PyDict::new(py);
    if let Some(rec) = &o.recorder {
        for (k, c) in rec.channels.iter().enumerate() {
            let col: Vec<f64> = rec.rows.iter().map(|r| r[k]).collect();
            ch.set_item(c.name(), col.into_pyarray(py))?;
        }
    }
    d.set_item("channels", ch)?;
    d.set_item("energy", energy_dict(py, &o.summary.energy)?)?;
    d.set_item(
        "energy_at_settle",
        energy_dict(py, &o.summary.energy_at_settle)?,
    )?;
    d.set_item("fault", o.summary.fault)?;
    d.set_item("faults_text", o.faults_text.clone())?;
    d.set_item("valid", o.summary.valid())?;
    d.set_item("why", o.summary.invalid.clone())?;
    d.set_item("steps", o.summary.steps)?;
    d.set_item("settle_step", o.summary.settle_step)?;
    let period = 1.0 / f64::from(sc.firmware.pwm_hz);
    d.set_item("period_s", period)?;
    d.set_item("wall_s", o.wall_s)?;
    // The run's summary: `hal_sim::summary::RunSummary`'s fields (what `regen run` prints),
    // and the mean power of every ledger flow after settling.
    let r = &o.summary;
    let s = PyDict::new(py);
    s.set_item("name", &r.name)?;
    s.set_item("duration_s", r.duration_s)?;
    s.set_item("settle_s", r.settle_s)?;
    s.set_item("mean_power_w", r.mean_power_w)?;
    s.set_item("peak_force_n", r.peak_force_n)?;
    s.set_item("peak_force_t_s", r.peak_force_t_s)?;
    s.set_item("peak_force_settled_n", r.peak_force_settled_n)?;
    s.set_item("fault_t_s", r.fault_t_s)?;
    s.set_item("wall_s", o.wall_s)?;
    s.set_item("real_time_factor", sc.duration_s / o.wall_s.max(1e-12))?;
    s.set_item("energy_residual_j", o.summary.energy.residual())?;
    s.set_item("energy_residual_rel", o.summary.energy.relative_residual())?;
    s.set_item("fault", o.summary.fault)?;
    s.set_item("valid", o.summary.valid())?;
    s.set_item("why", o.summary.invalid.clone())?;
    // Mean power of every flow after settle_s, W: ΔE over the periods after the settle step.
    let span = (o.summary.steps - o.summary.settle_step) as f64 * period;
    if span > 0.0 {
        for ((k, a), (_, b)) in energy_fields(&o.summary.energy)
            .into_iter()
            .zip(energy_fields(&o.summary.energy_at_settle))
        {
            if !k.starts_with("stored") {
                s.set_item(format!("p_{k}_w"), (a - b) / span)?;
            }
        }
    }
    d.set_item("summary", s)?;
    Ok(d.into_any().unbind())
}

fn sizing_dict<'py>(py: Python<'py>, s: &analytic::Sizing) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("c_short_n_s_per_m", s.c_short)?;
    d.set_item("f_rat_n", s.f_rat)?;
    d.set_item("i_c", s.i_c)?;
    d.set_item("i_f", s.i_f)?;
    d.set_item("i_v", s.i_v)?;
    d.set_item("i_m", s.i_m)?;
    Ok(d)
}

/// The reference device's sizing indices (eq. 6–12), as `regen sizing` prints them: `paper`
/// (9/4 formula with K_e = `ke_paper`) and `consistent` (3/2, the simulator's per-phase peak
/// K_e).
#[pyfunction]
#[pyo3(signature = (ke_paper = 0.77))]
fn sizing(py: Python<'_>, ke_paper: f64) -> PyResult<Py<PyAny>> {
    if !(ke_paper.is_finite() && ke_paper > 0.0 && ke_paper < 100.0) {
        return Err(err(format!(
            "ke_paper = {ke_paper}: must be in (0, 100) V·s/rad"
        )));
    }
    let m = Machine::default();
    let s = Screw::default();
    let dc = DesignCase::default();
    let d = PyDict::new(py);
    let p = analytic::sizing(ke_paper, &m, &s, &dc, DampingFormula::Paper);
    let c = analytic::sizing(m.ke_v_s_per_rad, &m, &s, &dc, DampingFormula::PerPhasePeak);
    d.set_item("paper", sizing_dict(py, &p)?)?;
    d.set_item("consistent", sizing_dict(py, &c)?)?;
    Ok(d.into_any().unbind())
}

/// Harmonic-balance TMD power (eq. 14–23) of a sine-excited structure scenario at each load:
/// dict of arrays `r_load_ohm`, `c_e_n_s_per_m`, `velocity_amp_m_s`, `p_load_w`, `p_elec_w`,
/// plus `r_opt_ohm` (golden-section optimum in [1, 1e4] Ω), as `regen sweep` draws it.
#[pyfunction]
fn tmd_power(py: Python<'_>, scenario: &PyScenario, r_load_ohm: Vec<f64>) -> PyResult<Py<PyAny>> {
    let sc = &scenario.inner;
    let Drive::Structure {
        structure,
        excitation: Excitation::Sine { a0_m_s2, freq_hz },
    } = &sc.drive
    else {
        return Err(err(
            "drive: the analytic TMD power needs a structure with a sine excitation",
        ));
    };
    if let Some(r) = r_load_ohm.iter().find(|r| r.is_nan() || **r <= 0.0) {
        return Err(err(format!(
            "r_load_ohm = {r}: must be > 0 Ω (inf for open circuit)"
        )));
    }
    let model = |r: f64| {
        analytic::tmd_power(
            r,
            &sc.machine,
            &sc.screw,
            structure,
            *a0_m_s2,
            *freq_hz,
            DampingFormula::PerPhasePeak,
        )
    };
    let rows: Vec<_> = r_load_ohm.iter().map(|&r| model(r)).collect();
    let d = PyDict::new(py);
    let col = |f: fn(&analytic::TmdPower) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    d.set_item("r_load_ohm", col(|p| p.r_load).into_pyarray(py))?;
    d.set_item("c_e_n_s_per_m", col(|p| p.c_e).into_pyarray(py))?;
    d.set_item("velocity_amp_m_s", col(|p| p.velocity_amp).into_pyarray(py))?;
    d.set_item("p_load_w", col(|p| p.p_load).into_pyarray(py))?;
    d.set_item("p_elec_w", col(|p| p.p_elec).into_pyarray(py))?;
    d.set_item(
        "r_opt_ohm",
        analytic::optimum_load(|r| model(r).p_load, 1.0, 1e4),
    )?;
    Ok(d.into_any().unbind())
}

/// The two-way optimal controller for the reference model (`regen study design`): dict with
/// `opt` (the `[law.opt]` table: a, b, c, d), `p_full_state_w`, `p_lqg_w`,
/// `best_resistor_ohm`, `best_resistor_w`.
#[pyfunction]
#[pyo3(signature = (r_on_ohm = 0.0))]
fn design_two_way(py: Python<'_>, r_on_ohm: f64) -> PyResult<Py<PyAny>> {
    if !(r_on_ohm.is_finite() && (0.0..=100.0).contains(&r_on_ohm)) {
        return Err(err(format!("r_on_ohm = {r_on_ohm}: must be in [0, 100] Ω")));
    }
    let spec = hal_sim::lqg::LqgSpec {
        r_on: r_on_ohm,
        ..hal_sim::lqg::LqgSpec::reference()
    };
    let (d, (rb, pb)) = py
        .detach(|| hal_sim::lqg::design(&spec).map(|d| (d, spec.model.best_resistor(r_on_ohm))))
        .map_err(err)?;
    let out = PyDict::new(py);
    let opt = PyDict::new(py);
    let f = |v: &[f32]| v.iter().map(|x| *x as f64).collect::<Vec<f64>>();
    opt.set_item("a", f(&d.params.a))?;
    opt.set_item("b", f(&d.params.b))?;
    opt.set_item("c", f(&d.params.c))?;
    opt.set_item("d", f(&d.params.d))?;
    out.set_item("opt", opt)?;
    out.set_item("p_full_state_w", d.p_full_state)?;
    out.set_item("p_lqg_w", d.p_lqg)?;
    out.set_item("best_resistor_ohm", rb)?;
    out.set_item("best_resistor_w", pb)?;
    Ok(out.into_any().unbind())
}

/// Diagnose a record given as CSV text (`regen diagnose`'s parser and pipeline): returns
/// (report JSON text, extended model TOML, text report).
#[pyfunction]
#[pyo3(signature = (text, cross_text = None, cutoff_hz = None, filter_force = false, min_gain = 0.02))]
fn diagnose_csv(
    py: Python<'_>,
    text: String,
    cross_text: Option<String>,
    cutoff_hz: Option<f64>,
    filter_force: bool,
    min_gain: f64,
) -> PyResult<(String, String, String)> {
    use hal_sim::diagnose::{cross_check, diagnose, record::parse_csv, report, Options};
    if !(0.0..1.0).contains(&min_gain) {
        return Err(err(format!("--min-gain {min_gain} must be in [0,1)")));
    }
    py.detach(|| {
        let mut rec = parse_csv(&text, cutoff_hz).map_err(|e| e.to_string())?;
        if filter_force {
            rec.filter_force(cutoff_hz);
        }
        let opt = Options {
            min_holdout_gain: min_gain,
            ..Options::default()
        };
        let mut d = diagnose(&rec, &opt);
        if let Some(c) = &cross_text {
            let mut other = parse_csv(c, cutoff_hz).map_err(|e| e.to_string())?;
            if filter_force {
                other.filter_force(cutoff_hz);
            }
            cross_check(&mut d, &other);
        }
        Ok::<_, String>((
            report::json(&d),
            report::model_toml(&rec, &d),
            report::text(&rec, &d),
        ))
    })
    .map_err(err)
}

/// The recorder's channel names and the firmware registry's parameter names.
#[pyfunction]
fn names(py: Python<'_>) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    let ch: Vec<&str> = hal_sim::Channel::ALL.iter().map(|c| c.name()).collect();
    let ps: Vec<&str> = regen_fw::params::PARAMS.iter().map(|p| p.name).collect();
    d.set_item("channels", ch)?;
    d.set_item("parameters", ps)?;
    Ok(d.into_any().unbind())
}

#[pymodule]
fn _regensim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RegenError", m.py().get_type::<RegenError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyScenario>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sizing, m)?)?;
    m.add_function(wrap_pyfunction!(tmd_power, m)?)?;
    m.add_function(wrap_pyfunction!(design_two_way, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_csv, m)?)?;
    m.add_function(wrap_pyfunction!(names, m)?)?;
    Ok(())
}

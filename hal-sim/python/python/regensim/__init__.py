"""regensim: the regen-drive simulator, its analytic designs and the model diagnosis.

Every function runs the Rust code the ``regen`` command line runs (the firmware's control
core, unchanged, in closed loop with the simulated plant); this package adds no physics.
Units are SI throughout and named in the keys (``_s``, ``_w``, ``_ohm``, ...); energies in J.

    >>> import regensim as rs
    >>> sc = rs.Scenario.tmd(306.0)          # the reference TMD, 306 ohm per phase
    >>> run = rs.simulate(sc)                # 12 s closed loop, GIL released
    >>> run.summary["p_to_inverter_w"]       # mean power into the drive after settle_s, W

Refused input raises :class:`RegenError` (a ``ValueError``) carrying the command line's
message: the key, the value and the allowed range; the object is left unchanged.

A run that completes but is not a result (its protection latched, its energy ledger does not
close, its state left the model's range) is returned, as ``scipy.optimize`` returns a failed
fit, with ``valid = False`` and ``why`` saying why in one line (``regen run`` exits 1 with the
same line); its figures are not the device's. Check ``run.valid`` before using a power.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Union

import numpy as np

from ._regensim import RegenError, Scenario, __version__
from ._regensim import design_two_way as _design_two_way
from ._regensim import diagnose_csv as _diagnose_csv
from ._regensim import names as _names
from ._regensim import simulate as _simulate
from ._regensim import sizing as _sizing
from ._regensim import tmd_power as _tmd_power
from .study import study

__all__ = [
    "__version__",
    "RegenError",
    "Scenario",
    "RunResult",
    "Diagnosis",
    "simulate",
    "sizing",
    "tmd_power",
    "design_two_way",
    "diagnose",
    "study",
    "CHANNELS",
    "PARAMETERS",
]

_N = _names()
#: Names of the channels a scenario's ``record.channels`` may list.
CHANNELS: "list[str]" = list(_N["channels"])
#: Names of the firmware's registry parameters (console ``set`` names; ``[law.set]`` keys).
PARAMETERS: "list[str]" = list(_N["parameters"])


@dataclass
class RunResult:
    """One closed-loop run.

    Attributes:
        channels: recorded channels, name -> float64 array, one sample per ``record.every``
            PWM periods (``t`` in s, ``x`` m, ``v`` m/s, ``force`` N, currents A, ``v_bus`` V,
            ``p_inverter`` W).
        energy: the energy ledger at the end of the run, field -> J.
        energy_at_settle: the ledger after the PWM period nearest ``settle_s``, J.
        fault: name of the latched firmware fault, or None.
        faults_text: the firmware console's ``faults`` reply (snapshot, safe state), or None.
        valid: whether the run is a result (``regen run``'s verdict: no protection latched,
            the energy ledger closed, the state inside the model's range).
        why: why the run is not a result, one line (None when ``valid``).
        steps: PWM periods simulated; settle_step: the one ``energy_at_settle`` follows.
        period_s: the PWM period, s. wall_s: wall time of the stepping, s.
        summary: the run's figures: name, durations (s), ``real_time_factor``,
            ``energy_residual_j``, ``energy_residual_rel``, ``fault``, ``valid``, ``why`` and
            the mean power of each ledger flow after ``settle_s`` as ``p_<flow>_w`` (W).
    """

    channels: Dict[str, np.ndarray]
    energy: Dict[str, float]
    energy_at_settle: Dict[str, float]
    fault: Optional[str]
    faults_text: Optional[str]
    valid: bool
    why: Optional[str]
    steps: int
    settle_step: int
    period_s: float
    wall_s: float
    summary: Dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line: the scenario, the verdict, the mean power (valid runs), the channels."""
        s = self.summary
        n = len(next(iter(self.channels.values()))) if self.channels else 0
        head = f"RunResult(name={s.get('name')!r}, duration_s={s.get('duration_s')}, "
        if self.valid:
            verdict = f"valid=True, mean_power_w={s.get('mean_power_w', float('nan')):.4g}"
        else:
            verdict = f"valid=False, why={self.why!r}"
        chans = f"channels=[{', '.join(self.channels)}] x {n}"
        return f"{head}{verdict}, fault={self.fault!r}, {chans})"


def simulate(scenario: Scenario, record: bool = True) -> RunResult:
    """Run ``scenario`` for its ``duration_s`` with the unchanged firmware (``regen run``'s loop).

    Args:
        scenario: the scenario (see :class:`Scenario`).
        record: keep the scenario's recorded channels (False: the ledger and summary only,
            which is what studies need).

    The GIL is released while Rust runs, so threads can run simulations side by side. The
    result says whether the run is a result (``valid``, ``why``); an invalid run is returned,
    not raised, so a study over a grid keeps its other points.
    """
    d = _simulate(scenario, record)
    return RunResult(**d)


def sizing(ke_paper: float = 0.77) -> Dict[str, Dict[str, float]]:
    """The reference device's sizing indices (eq. 6-12), as ``regen sizing`` prints them.

    Returns ``{"paper": {...}, "consistent": {...}}``, each with ``c_short_n_s_per_m`` (N.s/m),
    ``f_rat_n`` (N) and the dimensionless ``i_c``, ``i_f``, ``i_v``, ``i_m``. ``ke_paper``:
    the paper's K_e, V.s/rad.
    """
    return _sizing(ke_paper)


def tmd_power(scenario: Scenario, r_load_ohm: Any) -> Dict[str, Any]:
    """Harmonic-balance TMD power (eq. 14-23) at each load of ``r_load_ohm`` (ohm per phase).

    The scenario must be a structure with a sine excitation. Returns float64 arrays
    ``r_load_ohm``, ``c_e_n_s_per_m``, ``velocity_amp_m_s``, ``p_load_w`` (W in the load),
    ``p_elec_w`` (W converted) and ``r_opt_ohm``, the analytic optimum.
    """
    return _tmd_power(scenario, [float(r) for r in np.atleast_1d(r_load_ohm)])


def design_two_way(r_on_ohm: float = 0.0) -> Dict[str, Any]:
    """Design the two-way optimal (LQG) controller for the reference model (``regen study design``).

    Returns ``opt`` (the ``[law.opt]`` table, lists a, b, c, d: set it with
    ``scenario.set("law.opt", d["opt"])``), ``p_full_state_w`` and ``p_lqg_w`` (W, predicted),
    ``best_resistor_ohm`` and ``best_resistor_w``. ``r_on_ohm``: conduction resistance
    weighted in the design, ohm.
    """
    return _design_two_way(r_on_ohm)


@dataclass
class Diagnosis:
    """A diagnosis: ``report`` (the JSON report's structure, as ``regen diagnose --json``
    writes it), ``model_toml`` (the extended model as a scenario fragment, as ``--model``
    writes it) and ``text`` (the printed report)."""

    report: Dict[str, Any]
    model_toml: str
    text: str


def _record_csv(t: Any, x: Any, f: Any, columns: Dict[str, Any]) -> str:
    cols = {"t_s": t, "x_m": x, "f_N": f}
    meta = {}
    for k, v in columns.items():
        if np.ndim(v) == 0:
            meta[k] = float(v)
        else:
            cols[k] = v
    arrs = {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}
    n = len(arrs["t_s"])
    for k, a in arrs.items():
        if a.ndim != 1 or len(a) != n:
            raise RegenError(f"column `{k}`: {a.shape} samples, t_s has {n}")
    lines = [f"# {k} = {v!r}" for k, v in meta.items()]
    lines.append(",".join(arrs))
    # repr of a float64 is its shortest round-trip form: the parser reads back the same bits.
    stacked = np.column_stack(list(arrs.values()))
    lines.extend(",".join(repr(float(v)) for v in row) for row in stacked)
    return "\n".join(lines) + "\n"


def _csv_text(src: Union[str, "os.PathLike[str]", None], t: Any, x: Any, f: Any,
              columns: Dict[str, Any]) -> str:
    if src is not None:
        if t is not None or x is not None or f is not None or columns:
            raise RegenError("diagnose: give a path or arrays (t, x, f, ...), not both")
        with open(src, encoding="utf-8") as fh:
            return fh.read()
    if t is None or x is None or f is None:
        raise RegenError("diagnose: t (s), x (m) and f (N) are required")
    return _record_csv(t, x, f, columns)


def diagnose(
    path: Union[str, "os.PathLike[str]", None] = None,
    t: Any = None,
    x: Any = None,
    f: Any = None,
    *,
    cross: Union[str, "os.PathLike[str]", None] = None,
    cutoff_hz: Optional[float] = None,
    filter_force: bool = False,
    min_gain: float = 0.02,
    **columns_and_metadata: Any,
) -> Diagnosis:
    """Diagnose a measured record (``regen diagnose``): what the model gets wrong, the cause, the gain.

    Give either ``path`` (the CLI's CSV: ``t_s,x_m,f_N[,...]`` with ``# key = value`` metadata)
    or the arrays ``t`` (s), ``x`` (m), ``f`` (N); further keyword arrays are extra columns
    (e.g. ``x_ref_m=...``, ``i_q_A=...``), keyword scalars metadata (e.g. ``mass_kg=...``).
    ``cross``: a second record (path) to cross-check the extended model on. ``cutoff_hz``:
    low-pass for derived velocity/acceleration, Hz (default fs/20). ``filter_force``: filter the
    force too. ``min_gain``: held-out rss drop a finding must bring (fraction in [0, 1)).
    """
    text = _csv_text(path, t, x, f, columns_and_metadata)
    cross_text = None
    if cross is not None:
        with open(cross, encoding="utf-8") as fh:
            cross_text = fh.read()
    rep, model, txt = _diagnose_csv(text, cross_text, cutoff_hz, filter_force, min_gain)
    return Diagnosis(report=json.loads(rep), model_toml=model, text=txt)

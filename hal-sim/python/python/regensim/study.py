"""Studies: one scenario, many runs (a parameter grid and/or a seeded ensemble), mapped over a
Dask client or a local process pool, gathered into one table.

Each run is ``simulate(scenario with the point's keys set, record=False)``; its row is the
point's values followed by the run's summary (``p_<flow>_w`` mean powers after ``settle_s``, W;
the energy residual; the latched fault; the verdict ``valid``, ``why``) and whatever ``reduce`` returns. Points are validated
in the caller before anything is sent: a refused value raises :class:`RegenError` naming the
key, the value and the range, and no run starts.
"""

from __future__ import annotations

import itertools
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence

import numpy as np

from ._regensim import RegenError, Scenario
from ._regensim import simulate as _simulate

#: The Kanai-Tajimi / recorded-excitation seed key a seeded ensemble varies.
SEED_KEY = "drive.excitation.seed"


def points(grid: Optional[Mapping[str, Sequence[Any]]] = None,
           seeds: Optional[Iterable[int]] = None) -> List[Dict[str, Any]]:
    """The runs of a study: the Cartesian product of ``grid`` (key -> values, first key
    slowest) and, when ``seeds`` is given, of the seeds (``drive.excitation.seed``), fastest."""
    axes: List[tuple] = [(k, list(v)) for k, v in (grid or {}).items()]
    if seeds is not None:
        axes.append((SEED_KEY, [int(s) for s in seeds]))
    if not axes:
        return [{}]
    for k, vs in axes:
        if not vs:
            raise RegenError(f"{k}: no values to sweep")
    keys = [k for k, _ in axes]
    return [dict(zip(keys, combo)) for combo in itertools.product(*(vs for _, vs in axes))]


def _scenario_at(base: Scenario, point: Mapping[str, Any]) -> Scenario:
    sc = base.copy()
    for k, v in point.items():
        sc.set(k, v)
    return sc


def run_point(scenario_toml: str, point: Mapping[str, Any],
              reduce: Optional[Callable[[Any], Mapping[str, Any]]] = None) -> Dict[str, Any]:
    """One study run (what each worker executes): the scenario from its TOML with ``point``'s
    keys set, simulated without recording unless ``reduce`` needs the channels. Returns the row."""
    sc = _scenario_at(Scenario.from_toml(scenario_toml), point)
    d = _simulate(sc, reduce is not None)
    row: Dict[str, Any] = dict(point)
    for k, v in d["summary"].items():
        if k not in ("name", "wall_s", "real_time_factor"):
            row[k] = v
    if reduce is not None:
        from . import RunResult

        row.update(reduce(RunResult(**d)))
    return row


def _table(rows: List[Dict[str, Any]], as_pandas: Optional[bool]):
    cols: List[str] = []
    for r in rows:
        cols.extend(k for k in r if k not in cols)
    if as_pandas is not False:
        try:
            import pandas as pd
        except ImportError:
            if as_pandas:
                raise
        else:
            return pd.DataFrame(rows, columns=cols)

    def dtype(k: str):
        vals = [r.get(k) for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in vals):
            return np.bool_
        if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in vals):
            return np.int64
        if all(isinstance(v, (int, float, np.number)) for v in vals):
            return np.float64
        return object

    dt = np.dtype([(k, dtype(k)) for k in cols])
    out = np.empty(len(rows), dtype=dt)
    for i, r in enumerate(rows):
        out[i] = tuple(r.get(k) for k in cols)
    return out


def study(
    scenario: Scenario,
    grid: Optional[Mapping[str, Sequence[Any]]] = None,
    *,
    seeds: Optional[Iterable[int]] = None,
    client: Any = None,
    max_workers: Optional[int] = None,
    reduce: Optional[Callable[[Any], Mapping[str, Any]]] = None,
    as_pandas: Optional[bool] = None,
):
    """Run ``scenario`` at every point of ``grid`` x ``seeds`` and gather the rows into a table.

    Args:
        scenario: the base scenario.
        grid: key -> values (keys as :meth:`Scenario.set` takes them: sweep names such as
            ``r_load_ohm`` (ohm) or ``a0_m_s2`` (m/s^2), registry names, dotted paths).
        seeds: a seeded ensemble: the values of ``drive.excitation.seed`` (Kanai-Tajimi).
        client: a ``dask.distributed.Client``: runs are mapped over its workers
            (``client.map``, ``pure=False``) and gathered in order. None: a local process pool
            of ``max_workers`` processes (``max_workers=1``: in this process, no pool).
        reduce: optional picklable function ``RunResult -> dict`` adding columns per run
            (the run then records the scenario's channels).
        as_pandas: True/False to force or refuse a ``pandas.DataFrame``; None: pandas if
            installed, else a NumPy structured array.

    Returns: one row per point in the order of :func:`points`.
    """
    pts = points(grid, seeds)
    for p in pts:  # refuse bad values before anything runs (the CLI's messages)
        _scenario_at(scenario, p)
    text = scenario.to_toml()
    if client is not None:
        futures = client.map(run_point, [text] * len(pts), pts, [reduce] * len(pts), pure=False)
        rows = client.gather(futures)
    elif max_workers == 1 or len(pts) == 1:
        rows = [run_point(text, p, reduce) for p in pts]
    else:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=max_workers) as ex:
            rows = list(ex.map(run_point, [text] * len(pts), pts, [reduce] * len(pts)))
    return _table(list(rows), as_pandas)

"""Benchmarks of the Python route (figures printed, nothing asserted).

1. Call overhead on the 12 s reference TMD run (hal-sim/scenarios/tmd-306.toml): the Python
   call's wall time against the Rust stepping it contains (what Python adds), and against the
   `regen run` process (REGEN_BIN, default target/release/regen) end to end.
2. The Dask sweep's speed-up: the same 40-point sweep (8 loads x 5 amplitudes of the 12 s
   TMD) on a LocalCluster of 1 and of 2 worker processes, alternated, best of --repeat each.

    python hal-sim/python/examples/bench.py [--repeat 3]
"""

import argparse
import os
import pathlib
import re
import subprocess
import tempfile
import time

import regensim as rs

REPO = pathlib.Path(__file__).resolve().parents[3]
TMD = REPO / "hal-sim" / "scenarios" / "tmd-306.toml"


def call_overhead(repeat: int):
    exe = os.environ.get("REGEN_BIN", str(REPO / "target" / "release" / "regen"))
    sc = rs.Scenario.from_file(TMD)
    py, inner, cli, cli_step = [], [], [], []
    with tempfile.TemporaryDirectory() as out:
        for _ in range(repeat):
            t = time.perf_counter()
            r = rs.simulate(sc)
            py.append(time.perf_counter() - t)
            inner.append(r.wall_s)
            if os.path.exists(exe):
                t = time.perf_counter()
                p = subprocess.run([exe, "run", str(TMD), "--out", out], capture_output=True,
                                   text=True, check=True)
                cli.append(time.perf_counter() - t)
                m = re.search(r"simulated in ([0-9.]+) s", p.stdout)
                cli_step.append(float(m.group(1)))
    bp, bi = min(py), min(inner)
    print(f"12 s TMD run, best of {repeat}:")
    print(f"  Python simulate(): {bp * 1e3:8.1f} ms, of which Rust stepping {bi * 1e3:8.1f} ms"
          f"  -> Python call overhead {100 * (bp / bi - 1):+.2f} %")
    if cli:
        bc = min(cli)
        print(f"  regen run process: {bc * 1e3:8.1f} ms end to end (stepping "
              f"{min(cli_step) * 1e3:.0f} ms as it prints; {exe})")
        print(f"  -> Python call / CLI process: {100 * (bp / bc - 1):+.2f} %")
    else:
        print(f"  (no CLI binary at {exe}: set REGEN_BIN)")


def dask_speedup(repeat: int):
    from dask.distributed import Client, LocalCluster

    grid = {"r_load_ohm": [30.0, 60.0, 100.0, 200.0, 306.0, 500.0, 700.0, 1000.0],
            "a0_m_s2": [0.25, 0.5, 0.75, 1.0, 1.25]}
    sc = rs.Scenario.tmd()
    times = {1: [], 2: []}
    clusters, clients = [], {}
    try:
        for n in (1, 2):
            c = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                             host="127.0.0.1", dashboard_address=None)
            clusters.append(c)
            clients[n] = Client(c)
        rs.study(sc, {"r_load_ohm": [306.0, 306.0]}, client=clients[1])  # warm the workers
        rs.study(sc, {"r_load_ohm": [306.0, 306.0]}, client=clients[2])
        for _ in range(repeat):
            for n in (1, 2):
                t = time.perf_counter()
                tab = rs.study(sc, grid, client=clients[n])
                times[n].append(time.perf_counter() - t)
                assert len(tab) == 40
    finally:
        for c in clients.values():
            c.close()
        for c in clusters:
            c.close()
    t1, t2 = min(times[1]), min(times[2])
    print(f"Dask sweep of 40 x 12 s TMD runs, best of {repeat} (alternated in one process):")
    print(f"  1 worker {t1:6.2f} s   2 workers {t2:6.2f} s   speed-up {t1 / t2:.2f}x"
          f"   (machine load now: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-dask", action="store_true")
    a = ap.parse_args()
    call_overhead(max(a.repeat, 5))
    if not a.skip_dask:
        dask_speedup(a.repeat)

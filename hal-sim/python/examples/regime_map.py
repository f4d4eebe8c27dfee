"""Regime map: where two-way power flow pays for its losses.

The reference TMD on a seeded Kanai-Tajimi base excitation (omega_g = pi rad/s, zeta_g = 0.6),
run in closed loop with the firmware's one-way (regenerative only) and two-way (LQG, designed
by ``design_two_way``) laws over excitation intensity s0 x drive switching loss k_sw, each point
averaged over a seeded ensemble, mapped over Dask. Net power = power into the drive less its
switching and conduction losses (the logic supply is the same for both laws), W.

    python hal-sim/python/examples/regime_map.py                      # LocalCluster, 2 workers
    python hal-sim/python/examples/regime_map.py --scheduler tcp://host:8786
    python hal-sim/python/examples/regime_map.py --no-dask            # local process pool

Writes OUT/regime-map.csv and OUT/regime-map.svg (and .png when matplotlib is installed);
OUT is regen-out/ by default (the reviewed figures in docs/figures/ are replaced only by
asking for it: --out docs/figures).
"""

import argparse
import math
import pathlib
import time

import numpy as np

import regensim as rs


def base_scenario(duration_s: float, settle_s: float, r_on_ohm: float) -> rs.Scenario:
    sc = rs.Scenario.tmd()
    sc.set("drive.excitation", {"kind": "kanai_tajimi", "s0": 0.01, "omega_g": math.pi,
                                "zeta_g": 0.6, "seed": 1})
    sc.set("settle_s", settle_s)
    sc.set("duration_s", duration_s)
    sc.set("losses.r_on_ohm", r_on_ohm)
    sc.set("law.kind", "two_way")
    sc.set("law.opt", rs.design_two_way(r_on_ohm)["opt"])  # one_way runs the same design
    return sc


def svg_map(path, xs, ys, z, xlabel, ylabel, title):
    """A heat map of z (rows: ys, columns: xs) in plain SVG: blue where z > 0 (two-way wins),
    red where z < 0, the shade on a square-root scale of |z|, the number in each cell, and a
    colour bar on the right that gives the scale in W."""
    w, h, l, t, cw, ch = 840, 520, 110, 50, 600 / len(xs), 400 / len(ys)
    m = max(1e-12, float(np.nanmax(np.abs(z))))

    def colour(v):
        a = min(1.0, abs(v) / m) ** 0.5
        return f"rgba(40,90,200,{a:.2f})" if v > 0 else f"rgba(210,50,40,{a:.2f})"

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
           'font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<text x="{l + 300}" y="25" text-anchor="middle" font-size="15">{title}</text>']
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            v = z[i, j]
            px, py = l + j * cw, t + (len(ys) - 1 - i) * ch
            out.append(f'<rect x="{px:.1f}" y="{py:.1f}" width="{cw:.1f}" height="{ch:.1f}" '
                       f'fill="{colour(v)}" stroke="#888"/>')
            out.append(f'<text x="{px + cw / 2:.1f}" y="{py + ch / 2 + 4:.1f}" '
                       f'text-anchor="middle">{v:+.3g}</text>')
    for j, x in enumerate(xs):
        out.append(f'<text x="{l + (j + 0.5) * cw:.1f}" y="{t + 400 + 18}" '
                   f'text-anchor="middle">{x:.3g}</text>')
    for i, y in enumerate(ys):
        out.append(f'<text x="{l - 8}" y="{t + (len(ys) - 0.5 - i) * ch + 4:.1f}" '
                   f'text-anchor="end">{y:.3g}</text>')
    out.append(f'<text x="{l + 300}" y="{t + 400 + 40}" text-anchor="middle">{xlabel}</text>')
    out.append(f'<text x="20" y="{t + 200}" transform="rotate(-90 20 {t + 200})" '
               f'text-anchor="middle">{ylabel}</text>')
    # The colour bar: -m (bottom) to +m (top) in 80 bands, ticks at 0, ±m/4 and ±m (the
    # square-root shade makes ±m/4 half as dark as ±m).
    bx, bw, n = l + 600 + 30, 22, 80
    for k in range(n):
        v = m * (1 - 2 * (k + 0.5) / n)
        out.append(f'<rect x="{bx}" y="{t + k * 400 / n:.2f}" width="{bw}" '
                   f'height="{400 / n + 0.3:.2f}" fill="{colour(v)}"/>')
    out.append(f'<rect x="{bx}" y="{t}" width="{bw}" height="400" fill="none" stroke="#444"/>')
    for v in (m, m / 4, 0.0, -m / 4, -m):
        y = t + 200 * (1 - v / m)
        out.append(f'<line x1="{bx + bw}" y1="{y:.1f}" x2="{bx + bw + 5}" y2="{y:.1f}" '
                   'stroke="#444"/>')
        out.append(f'<text x="{bx + bw + 8}" y="{y + 4:.1f}">'
                   f'{"0" if v == 0 else format(v, "+.2g")}</text>')
    out.append(f'<text x="{bx + bw + 58}" y="{t + 200}" '
               f'transform="rotate(-90 {bx + bw + 58} {t + 200})" text-anchor="middle">'
               'W (blue: two-way pays)</text>')
    out.append("</svg>")
    pathlib.Path(path).write_text("\n".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scheduler", help="address of a running Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    ap.add_argument("--no-dask", action="store_true", help="local process pool instead")
    ap.add_argument("--seeds", type=int, default=2, help="ensemble size per point")
    ap.add_argument("--duration", type=float, default=40.0, help="simulated s per run")
    ap.add_argument("--settle", type=float, default=10.0, help="s before averaging")
    ap.add_argument("--out", default="regen-out", help="output folder (default: regen-out)")
    a = ap.parse_args()

    s0 = [1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2]  # (m/s²)²/(rad/s)
    k_sw = [25e-9, 50e-9, 100e-9, 200e-9]  # s; the default drive is 50 ns
    grid = {"law.kind": ["one_way", "two_way"], "losses.k_sw_s": k_sw,
            "drive.excitation.s0": s0}
    sc = base_scenario(a.duration, a.settle, 0.02)
    t0 = time.time()
    if a.no_dask:
        table = rs.study(sc, grid, seeds=range(1, a.seeds + 1), max_workers=a.workers,
                         as_pandas=False)
    else:
        from dask.distributed import Client, LocalCluster

        cluster = None
        try:
            if a.scheduler:
                client = Client(a.scheduler)
            else:
                cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
                client = Client(cluster)
            table = rs.study(sc, grid, seeds=range(1, a.seeds + 1), client=client,
                             as_pandas=False)
            client.close()
        finally:
            if cluster is not None:
                cluster.close()
    wall = time.time() - t0
    net = (table["p_to_inverter_w"] - table["p_switching_loss_w"]
           - table["p_conduction_loss_w"])
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = ["s0_m2_s3,k_sw_s,net_one_way_w,net_two_way_w,two_way_gain_w,faults_two_way"]
    z = np.zeros((len(k_sw), len(s0)))
    for i, k in enumerate(k_sw):
        for j, s in enumerate(s0):
            sel = (table["losses.k_sw_s"] == k) & (table["drive.excitation.s0"] == s)
            one = net[sel & (table["law.kind"] == "one_way")].mean()
            two_sel = sel & (table["law.kind"] == "two_way")
            two = net[two_sel].mean()
            faults = sum(f is not None for f in table["fault"][two_sel])
            z[i, j] = two - one
            rows.append(f"{s:.6g},{k:.6g},{one:.6g},{two:.6g},{two - one:.6g},{faults}")
            print(f"s0 {s:8.3g}  k_sw {k:8.3g} s   one-way {one:8.3f} W   two-way {two:8.3f} W"
                  f"   gain {two - one:+8.3f} W" + (f"   ({faults} faulted)" if faults else ""))
    (out / "regime-map.csv").write_text("\n".join(rows) + "\n")
    title = f"two-way minus one-way net power, W ({a.seeds} seeds × {a.duration:g} s)"
    svg_map(out / "regime-map.svg", s0, [k * 1e9 for k in k_sw], z,
            "Kanai–Tajimi intensity s0, (m/s²)²/(rad/s)", "switching loss k_sw, ns", title)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.colors import SymLogNorm

        fig, ax = plt.subplots(figsize=(7.5, 4.6))
        lim = float(np.abs(z).max())
        pc = ax.pcolormesh(np.arange(len(s0) + 1), np.arange(len(k_sw) + 1), z, cmap="RdBu",
                           norm=SymLogNorm(linthresh=0.01, vmin=-lim, vmax=lim))
        for i in range(len(k_sw)):
            for j in range(len(s0)):
                ax.text(j + 0.5, i + 0.5, f"{z[i, j]:+.3g}", ha="center", va="center")
        ax.set_xticks(np.arange(len(s0)) + 0.5, [f"{s:.3g}" for s in s0])
        ax.set_yticks(np.arange(len(k_sw)) + 0.5, [f"{k * 1e9:.0f}" for k in k_sw])
        ax.set_xlabel("Kanai–Tajimi intensity s0, (m/s²)²/(rad/s)")
        ax.set_ylabel("switching loss k_sw, ns")
        ax.set_title(title, fontsize=10)
        fig.colorbar(pc, label="W (blue: two-way pays)")
        fig.tight_layout()
        fig.savefig(out / "regime-map.png", dpi=90)
    except ImportError:
        pass
    print(f"{len(table)} runs in {wall:.1f} s wall; wrote {out}/regime-map.csv, .svg")


if __name__ == "__main__":
    main()

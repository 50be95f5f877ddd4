"""Soak: many phone peers for a long game under a cellular network and a
steady stream of faults; does the run still hold, and does any peer grow?

    python benchmarks/soak.py                          # 50 phones, 10 Hz, 10 min, 3g, a fault every 30 s
    python benchmarks/soak.py --phones 10 --minutes 2  # a quick look

The game is a pursuit on the 80 m x 40 m field played live (``bearcat
run``: the ground station and every phone its own process, shim network):
one evader and ``phones - 1`` pursuers, each walking a small loop of its own
and sending a GPS fix ten times a second, none close enough to another to
end the game, so it lasts its full time. Two pursuers are aided (the ground
station computes their guidance at 2 Hz, against every other pursuer).
From 30 s on, every ``--fault-every`` seconds one fault of the rotation
below hits a different phone; each lasts less than the lease, so none ends
the game. The lease is 30 s rather than 10 s: with fifty phones on two
cores a restarted phone took 7 to 15 s to start again and rejoin, and one
that takes longer than the lease forfeits the game.

Every 10 s the memory of each peer's process is sampled (the launcher's
process tree, matched to peers by their ``--id``): its unique set size, the
memory that is its own and would be freed if it exited (a leak grows it),
and its resident size, which also counts the libraries every peer shares. A
restarted phone is a new process; its memory counts from its restart. The report:
per peer, the memory after a three-minute warm-up, at the end, and the growth
per minute fitted over the rest (least squares, 95 % interval); the run
checker's findings; ``soak.png`` plots every peer's memory over time and
``soak.json`` holds the samples.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
from scipy import stats

SAMPLE_EVERY = 10.0  # s
WARM_UP = 180.0  # s: imports, caches and buffers fill; the ground station's took 2.5 min in a 50-phone soak
LEASE = 30.0  # s
ROTATION = (
    {"kind": "pause", "duration": 3.0},
    {"kind": "partition", "duration": 5.0},
    {"kind": "outage", "duration": 5.0},
    {"kind": "degrade", "profile": "3g-degraded", "duration": 10.0},
    {"kind": "gps", "mode": "spoof", "position": [40.0, 20.0], "duration": 5.0},
    {"kind": "clock", "offset": 1.0, "drift": 0.001},
    {"kind": "restart", "duration": 1.0},
    {"kind": "gps", "mode": "freeze", "duration": 5.0},
)


def scenario_text(phones: int, minutes: float, rate: float, netem: str) -> str:
    """A pursuit game nobody wins before the time limit: ``phones - 1`` pursuers on loops of their own."""
    pursuers = phones - 1
    columns = int(np.ceil(np.sqrt(pursuers * 1.5)))
    rows = int(np.ceil(pursuers / columns))
    lines = [
        "[scenario]",
        'name = "soak"',
        'description = "a long game of many phones under faults"',
        'map = "field-80x40"',
        'game = "pursuit"',
        f"time_limit = {minutes * 60.0}",
        f'netem = "{netem}"',
        f"lease = {LEASE}",
        "seed = 0",
        "",
        "[rules]",
        "capture_radius = 0.5",
        "",
        "[guidance]",
        "rate = 2.0",
        "",
    ]

    def walker(name: str, team: str, x: float, y: float, side: float, aided: bool) -> list[str]:
        loop = [[x, y], [x + side, y], [x + side, y + side], [x, y + side]]
        return [
            "[[agent]]",
            f'id = "{name}"',
            f'team = "{team}"',
            f"start = [{x}, {y}]",
            "speed = 1.5",
            'behaviour = "waypoints"',
            f"aided = {'true' if aided else 'false'}",
            f"fix_rate = {rate}",
            f"options = {{ points = {json.dumps(loop)}, loop = true }}",
            "",
        ]

    lines += walker("evader", "evader", 70.0, 15.0, 6.0, False)
    for k in range(pursuers):
        x, y = 3.0 + (k % columns) * (55.0 / columns), 3.0 + (k // columns) * (34.0 / rows)
        lines += walker(f"p{k + 1}", "pursuer", round(x, 2), round(y, 2), 2.5, k < 2)
    return "\n".join(lines)


def plan_text(phones: int, minutes: float, every: float) -> str:
    """One fault of the rotation every ``every`` seconds, each on the next phone."""
    names = ["evader", *(f"p{k + 1}" for k in range(phones - 1))]
    lines = []
    for n, at in enumerate(np.arange(every, minutes * 60.0 - every / 2, every)):
        fault = dict(ROTATION[n % len(ROTATION)])
        target = names[(7 * n) % len(names)]
        if fault["kind"] == "partition":
            fault["groups"] = [[target]]
        else:
            fault["target"] = target
        lines += ["[[fault]]", f"at = {float(at)}"]
        lines += [f"{key} = {json.dumps(value)}" for key, value in fault.items()]
        lines.append("")
    return "\n".join(lines)


def peer_of(process: psutil.Process) -> str | None:
    """The peer a process of the launcher's tree runs (its ``--id``), or None."""
    try:
        command = process.cmdline()
    except psutil.Error:
        return None
    if "peer" not in command or "--id" not in command:
        return None
    return command[command.index("--id") + 1]


def sample(launcher: psutil.Process, t: float, samples: dict) -> None:
    """Each peer process's unique and resident memory now (MiB), keyed by peer and pid (a restart is a new pid)."""
    try:
        children = launcher.children(recursive=True)
    except psutil.Error:
        return
    for process in children:
        name = peer_of(process)
        if name is None:
            continue
        try:
            memory = process.memory_full_info()
        except psutil.Error:
            continue
        samples.setdefault(name, {}).setdefault(str(process.pid), []).append(
            (t, memory.uss / 2**20, memory.rss / 2**20)
        )


def growth(series: list[tuple[float, float]]) -> dict | None:
    """Unique memory after the warm-up, at the end, and its fitted growth per minute with a 95 % interval."""
    settled = [(t, m) for t, m, _ in series if t - series[0][0] >= WARM_UP]
    if len(settled) < 3:
        return None
    t, m = np.array(settled).T
    fit = stats.linregress(t / 60.0, m)
    half = stats.t.ppf(0.975, len(t) - 2) * fit.stderr
    return {
        "after_warm_up_mb": float(m[0]),
        "end_mb": float(m[-1]),
        "growth_mb": float(m[-1] - m[0]),
        "mb_per_min": float(fit.slope),
        "mb_per_min_95": [float(fit.slope - half), float(fit.slope + half)],
        "minutes": float((t[-1] - t[0]) / 60.0),
    }


def plot(samples: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5))
    for name, processes in sorted(samples.items()):
        for series in processes.values():
            t, m, _ = np.array(series).T
            ax.plot(t / 60.0, m, lw=1.5 if name == "gs" else 0.6, color="C3" if name == "gs" else "C0", alpha=0.8)
    ax.set_xlabel("minutes since launch")
    ax.set_ylabel("unique memory (MiB)")
    ax.set_title("every peer's memory through the soak (red: the ground station)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--phones", type=int, default=50)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=10.0, help="GPS fixes per second per phone")
    parser.add_argument("--netem", default="3g")
    parser.add_argument("--fault-every", type=float, default=30.0, help="s between faults")
    parser.add_argument("--out", type=Path, default=None, help="run and report directory (default: a new temp dir)")
    args = parser.parse_args()
    if args.phones < 2:
        parser.error("--phones: a pursuit needs an evader and at least one pursuer")
    out = args.out or Path(tempfile.mkdtemp(prefix="bearcat-soak-"))
    out.mkdir(parents=True, exist_ok=True)
    scenario, plan, run = out / "soak.toml", out / "soak-faults.toml", out / "run"
    scenario.write_text(scenario_text(args.phones, args.minutes, args.rate, args.netem))
    plan.write_text(plan_text(args.phones, args.minutes, args.fault_every))
    command = [sys.executable, "-m", "bearcat", "run", str(scenario), "--faults", str(plan), "--out", str(run)]
    print(
        f"soak: {args.phones} phones at {args.rate:g} Hz for {args.minutes:g} min under {args.netem}, "
        f"a fault every {args.fault_every:g} s; run directory {run}",
        flush=True,
    )
    started = time.monotonic()
    samples: dict[str, dict[str, list]] = {}
    with open(out / "launcher.log", "w") as log:
        launcher = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        watched = psutil.Process(launcher.pid)
        while launcher.poll() is None:
            t = time.monotonic() - started
            sample(watched, t, samples)
            now = [s[-1] for p in samples.values() for s in p.values() if t - s[-1][0] < SAMPLE_EVERY]
            if now and int(t) % 60 < SAMPLE_EVERY:
                print(
                    f"  {t / 60:5.1f} min: {len(now)} peer processes, {sum(m[1] for m in now):.0f} MiB "
                    f"their own, {max(m[2] for m in now):.0f} MiB the largest resident",
                    flush=True,
                )
            time.sleep(SAMPLE_EVERY - (time.monotonic() - started) % SAMPLE_EVERY)
    print(f"the launcher exited with {launcher.returncode} after {(time.monotonic() - started) / 60:.1f} min")

    report = {"phones": args.phones, "minutes": args.minutes, "rate": args.rate, "netem": args.netem, "peers": {}}
    for name, processes in samples.items():
        longest = max(processes.values(), key=len)
        report["peers"][name] = {"processes": len(processes), **(growth(longest) or {})}
    fitted = {n: p for n, p in report["peers"].items() if "mb_per_min" in p}
    print(f"\n{'peer':<8} {'procs':>5} {'after 3 min':>12} {'end':>8} {'growth':>8} {'MiB/min (95 %)':>24}")
    for name in sorted(fitted, key=lambda n: -fitted[n]["mb_per_min"])[:10]:
        p = fitted[name]
        low, high = p["mb_per_min_95"]
        print(
            f"{name:<8} {p['processes']:>5} {p['after_warm_up_mb']:>10.1f} M {p['end_mb']:>6.1f} M "
            f"{p['growth_mb']:>+6.1f} M {p['mb_per_min']:>+8.3f} [{low:+.3f}, {high:+.3f}]"
        )
    if fitted:
        rates = np.array([p["mb_per_min"] for n, p in fitted.items() if n != "gs"])
        if rates.size:
            print(
                f"phones: growth per minute median {np.median(rates):+.3f} MiB, "
                f"largest {rates.max():+.3f} MiB ({len(rates)} phones fitted)"
            )
    checked = subprocess.run([sys.executable, "-m", "bearcat", "check", str(run)], capture_output=True, text=True)
    print("\n" + checked.stdout + checked.stderr)
    report["check_exit"] = checked.returncode
    report["check"] = checked.stdout
    (out / "soak.json").write_text(json.dumps({**report, "samples": samples}, indent=1))
    plot(samples, out / "soak.png")
    print(f"report: {out / 'soak.json'}, plot: {out / 'soak.png'}")
    return 0 if launcher.returncode == 0 and checked.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

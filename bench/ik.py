"""IK speed: spar-py's closed-form PUMA 762 IK against Robotics Toolbox's ``ikine_a``.

Run from the project root: ``.venv/bin/python -m bench.ik [--n 10000] [--repeats 5]``.
Reports the median over repeats of microseconds per pose for

- ``Robot.ik_batch`` on n random reachable poses (all solutions, one call);
- ``Robot.ik`` called once per pose (all solutions);
- Robotics Toolbox for Python's analytic ``Puma560().ikine_a`` (one configuration
  per call, as it is designed), and the eight calls it takes for all configurations.

The two arms differ (PUMA 762 in mm here, RTB's Puma 560 in m) but the closed
form is the same arithmetic, so the per-pose cost compares like with like.
"""
from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
RTB_CONFIGS = ("lun", "luf", "ldn", "ldf", "run", "ruf", "rdn", "rdf")  # left/right, up/down, no flip/flip


def median_us(fn: Callable[[], object], per: int, repeats: int) -> float:
    """Median over ``repeats`` runs of fn's wall time, in microseconds per item (``per`` items a run)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) / per * 1e6


def bench_spar(n: int, n_single: int, repeats: int) -> tuple[float, float, float]:
    """(batch us/pose, single us/pose, mean solutions per pose) for the PUMA 762."""
    from spar_py.kinematics import Robot

    robot = Robot.from_yaml(PUMA)
    rng = np.random.default_rng(1)
    q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))
    T = robot.fk_batch(q)  # reachable by construction
    _, ok = robot.ik_batch(T)
    if not ok.any(axis=1).all():
        raise SystemExit("bench: a reachable pose got no IK solution")
    batch = median_us(lambda: robot.ik_batch(T), n, repeats)
    Ts = T[:n_single]
    single = median_us(lambda: [robot.ik(t) for t in Ts], n_single, repeats)
    return batch, single, float(ok.sum(axis=1).mean())


def bench_rtb(n: int, repeats: int) -> tuple[float, float, float] | None:
    """(us per ikine_a call, us for all 8 configurations of a pose, success rate) or None if RTB is absent."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return None
    puma = rtb.models.DH.Puma560()
    rng = np.random.default_rng(2)
    qlim = np.asarray(puma.qlim)
    q = rng.uniform(qlim[0], qlim[1], size=(n, 6))
    Ts = [puma.fkine(qi) for qi in q]
    ok = sum(bool(puma.ikine_a(T).success) for T in Ts)
    one = median_us(lambda: [puma.ikine_a(T) for T in Ts], n, repeats)
    every = median_us(lambda: [puma.ikine_a(T, config=c) for T in Ts for c in RTB_CONFIGS], n, repeats)
    return one, every, ok / n


def main(argv: list[str] | None = None) -> None:
    """Print the IK timings (microseconds per pose, medians) and the speed ratios to stdout."""
    ap = argparse.ArgumentParser(prog="python -m bench.ik", description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="poses for the batch run (default 10000)")
    ap.add_argument("--single", type=int, default=1000, help="poses for the one-call-per-pose runs")
    ap.add_argument("--rtb", type=int, default=200, help="poses for Robotics Toolbox (it is slow)")
    ap.add_argument("--repeats", type=int, default=5, help="repeats; medians are reported (default 5)")
    a = ap.parse_args(argv)

    batch, single, nsol = bench_spar(a.n, min(a.single, a.n), a.repeats)
    print(f"spar-py ik_batch   : {batch:9.2f} us/pose  (n = {a.n}, all solutions, "
          f"{nsol:.1f} in-limit rows/pose on average; median of {a.repeats})")
    print(f"spar-py ik (single): {single:9.2f} us/pose  (n = {min(a.single, a.n)}, one call per pose)")
    r = bench_rtb(a.rtb, a.repeats)
    if r is None:
        print("rtb ikine_a        : skipped: pip install -e '.[bench]'")
        return
    one, every, success = r
    print(f"rtb ikine_a        : {one:9.2f} us/pose  (n = {a.rtb}, one configuration per call, "
          f"{success:.0%} succeeded)")
    print(f"rtb ikine_a x 8    : {every:9.2f} us/pose  (all eight configurations)")
    print(f"ratio ikine_a / ik_batch      : {one / batch:8.1f}x  (all 8 configs: {every / batch:.1f}x)")
    print(f"ratio ikine_a / ik (single)   : {one / single:8.1f}x  (all 8 configs: {every / single:.1f}x)")


if __name__ == "__main__":
    main()

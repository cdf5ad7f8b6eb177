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
    from spar_py.kb import load_robot

    robot = load_robot(PUMA)
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


def run(n: int = 10_000, single: int = 1000, rtb: int = 200, repeats: int = 5) -> dict:
    """All the IK figures as data: microseconds per pose (medians of ``repeats``), ratios.

    Keys: ``n``, ``n_single``, ``n_rtb``, ``repeats``, ``batch_us``, ``single_us``,
    ``solutions_per_pose``, and, when Robotics Toolbox is installed (else None),
    ``rtb_us`` (one ``ikine_a`` call), ``rtb_all8_us`` (all eight configurations),
    ``rtb_success`` and the ratios ``rtb_over_batch``, ``rtb_all8_over_batch``,
    ``rtb_over_single``, ``rtb_all8_over_single``. The spar-py and RTB runs happen
    one after the other in the same process, so their ratio is a same-run figure.
    """
    n_single = min(single, n)
    batch, single_us, nsol = bench_spar(n, n_single, repeats)
    out: dict = {"n": n, "n_single": n_single, "n_rtb": rtb, "repeats": repeats,
                 "batch_us": batch, "single_us": single_us, "solutions_per_pose": nsol,
                 "rtb_us": None, "rtb_all8_us": None, "rtb_success": None,
                 "rtb_over_batch": None, "rtb_all8_over_batch": None,
                 "rtb_over_single": None, "rtb_all8_over_single": None}
    r = bench_rtb(rtb, repeats)
    if r is not None:
        one, every, success = r
        out.update(rtb_us=one, rtb_all8_us=every, rtb_success=success,
                   rtb_over_batch=one / batch, rtb_all8_over_batch=every / batch,
                   rtb_over_single=one / single_us, rtb_all8_over_single=every / single_us)
    return out


def main(argv: list[str] | None = None) -> None:
    """Print the IK timings (microseconds per pose, medians) and the speed ratios to stdout."""
    ap = argparse.ArgumentParser(prog="python -m bench.ik", description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="poses for the batch run (default 10000)")
    ap.add_argument("--single", type=int, default=1000, help="poses for the one-call-per-pose runs")
    ap.add_argument("--rtb", type=int, default=200, help="poses for Robotics Toolbox (it is slow)")
    ap.add_argument("--repeats", type=int, default=5, help="repeats; medians are reported (default 5)")
    a = ap.parse_args(argv)

    r = run(a.n, a.single, a.rtb, a.repeats)
    print(f"spar-py ik_batch   : {r['batch_us']:9.2f} us/pose  (n = {a.n}, all solutions, "
          f"{r['solutions_per_pose']:.1f} in-limit rows/pose on average; median of {a.repeats})")
    print(f"spar-py ik (single): {r['single_us']:9.2f} us/pose  (n = {r['n_single']}, one call per pose)")
    if r["rtb_us"] is None:
        print("rtb ikine_a        : skipped: pip install -e '.[bench]'")
        return
    print(f"rtb ikine_a        : {r['rtb_us']:9.2f} us/pose  (n = {a.rtb}, one configuration per call, "
          f"{r['rtb_success']:.0%} succeeded)")
    print(f"rtb ikine_a x 8    : {r['rtb_all8_us']:9.2f} us/pose  (all eight configurations)")
    print(f"ratio ikine_a / ik_batch      : {r['rtb_over_batch']:8.1f}x  "
          f"(all 8 configs: {r['rtb_all8_over_batch']:.1f}x)")
    print(f"ratio ikine_a / ik (single)   : {r['rtb_over_single']:8.1f}x  "
          f"(all 8 configs: {r['rtb_all8_over_single']:.1f}x)")


if __name__ == "__main__":
    main()

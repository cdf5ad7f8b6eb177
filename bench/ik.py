"""IK speed: spar-py's closed forms (PUMA, UR) and numeric fallback against Robotics Toolbox.

Run from the project root: ``.venv/bin/python -m bench.ik [--n 10000] [--repeats 5]``.
Reports the median over repeats of microseconds per pose for

- PUMA 762: ``Robot.ik_batch`` on n random reachable poses (all 8 branches, one call);
  ``Robot.ik`` called once per pose (every in-limit representation); Robotics Toolbox
  for Python's analytic ``Puma560().ikine_a`` (one configuration per call, as it is
  designed), and the eight calls it takes for all configurations. The two arms differ
  (PUMA 762 in mm here, RTB's Puma 560 in m) but the closed form is the same arithmetic.
- UR: the UR closed form's ``ik_batch`` (all 8 branches) for the UR5e file and for RTB's
  own UR5 table (``rtb.models.DH.UR5``, the same arm RTB solves), ``ik`` per pose (all
  512 in-limit representations of a +-360 deg arm), and RTB's UR5 ``ikine_LM`` (RTB has no
  analytic UR solver: Levenberg-Marquardt, one configuration per call).
- numeric: the multi-start DLS fallback's ``ik_batch`` on the PUMA with d5 = 95 mm.
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
UR5E = ROOT / "kb" / "robots" / "ur5e.yaml"
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

    batch, single, ok, _ = _time_ik(load_robot(PUMA), n, n_single, repeats, seed=1)
    return batch, single, float(ok.sum(axis=1).mean())


def _time_ik(robot, n: int, n_single: int, repeats: int, seed: int):
    """Time ``robot``'s IK on n in-limit poses (reachable by construction: fk of random joint
    vectors): (batch us/pose, single us/pose over the first n_single, ok (n, B), those poses)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))
    T = robot.fk_batch(q)
    _, ok = robot.ik_batch(T)
    if not ok.any(axis=1).all():
        raise SystemExit(f"bench: a reachable pose of {robot.name} got no IK solution")
    batch = median_us(lambda: robot.ik_batch(T), n, repeats)
    Ts = T[:n_single]
    single = median_us(lambda: [robot.ik(t) for t in Ts], n_single, repeats)
    return batch, single, ok, Ts


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


def _ur_robots() -> dict:
    """The UR5e from its file and RTB's UR5 table (standard DH, m -> mm) as spar-py robots."""
    from spar_py.kb import load_robot
    from spar_py.world.robot.model import Robot, standard_to_modified

    ur5 = np.array([[90, 0, 89.46], [0, -425, 0], [0, -392.2, 0], [90, 0, 109.1], [-90, 0, 94.65], [0, 0, 82.3]])
    std = np.column_stack([np.radians(ur5[:, 0]), ur5[:, 1], ur5[:, 2], np.zeros(6)])
    dh, flange = standard_to_modified(std)
    lim = np.radians([[-360, 360]] * 6)
    return {"ur5e": load_robot(UR5E), "ur5": Robot("ur5", dh, lim, np.eye(4), flange, 85.0, "mm")}


def bench_ur(n: int, n_single: int, repeats: int) -> dict:
    """UR closed form: batch and single us/pose, branches and rows per pose, for the UR5e and RTB's UR5."""
    out = {}
    for name, robot in _ur_robots().items():
        if robot.solver_name != "closed-form ur":
            raise SystemExit(f"bench: {name} is not solved by the UR closed form")
        batch, single, ok, Ts = _time_ik(robot, n, n_single, repeats, seed=3)
        rows = float(np.mean([len(robot.ik(t)) for t in Ts[:100]]))
        out[name] = {"batch_us": batch, "single_us": single, "branches_per_pose": float(ok.sum(axis=1).mean()),
                     "rows_per_pose": rows}
    return out


def bench_rtb_ur(n: int, repeats: int) -> tuple[float, float] | None:
    """(us per RTB UR5 ``ikine_LM`` call, success rate) or None if RTB is absent."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return None
    ur5 = rtb.models.DH.UR5()
    rng = np.random.default_rng(4)
    q = rng.uniform(-np.pi, np.pi, size=(n, 6))
    Ts = [ur5.fkine(qi) for qi in q]
    ok = sum(bool(ur5.ikine_LM(T).success) for T in Ts)
    return median_us(lambda: [ur5.ikine_LM(T) for T in Ts], n, repeats), ok / n


def bench_numeric(n: int, repeats: int) -> dict:
    """The numeric fallback on the PUMA 762 with d5 = 95 mm: batch us/pose, solutions found per pose,
    and the share of poses whose own configuration was among them."""
    import tempfile

    from spar_py.kb import load_robot

    text = PUMA.read_text().replace("  - {alpha: 90,  a: 0,   d: 0,", "  - {alpha: 90,  a: 0,   d: 95,")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "puma_d5.yaml"
        path.write_text(text)
        robot = load_robot(path)
    rng = np.random.default_rng(5)
    q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))
    T = robot.fk_batch(q)
    Q, ok = robot.ik_batch(T)
    d = np.abs(np.remainder(Q - q[:, None, :] + np.pi, 2 * np.pi) - np.pi).max(axis=2)
    return {"solver": robot.solver_name, "n": n, "batch_us": median_us(lambda: robot.ik_batch(T), n, repeats),
            "solutions_per_pose": float(ok.sum(axis=1).mean()), "solved": float(ok.any(axis=1).mean()),
            "own_found": float(((d < 1e-6) & ok).any(axis=1).mean())}


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
    ur = bench_ur(n, n_single, repeats)
    lm = bench_rtb_ur(max(1, rtb // 4), repeats)
    ur.update(rtb_lm_us=None if lm is None else lm[0], rtb_lm_success=None if lm is None else lm[1],
              rtb_lm_over_batch=None if lm is None else lm[0] / ur["ur5"]["batch_us"])
    out["ur"] = ur
    out["numeric"] = bench_numeric(max(10, n // 10), repeats)
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
    for name, u in ((k, v) for k, v in r["ur"].items() if isinstance(v, dict)):
        print(f"UR {name:5s} ik_batch  : {u['batch_us']:9.2f} us/pose  (all 8 branches; {u['branches_per_pose']:.1f} "
              f"in-limit per pose)   ik: {u['single_us']:.1f} us/pose ({u['rows_per_pose']:.0f} rows with turns)")
    if r["ur"]["rtb_lm_us"] is not None:
        print(f"rtb UR5 ikine_LM   : {r['ur']['rtb_lm_us']:9.2f} us/pose  (one configuration per call, "
              f"{r['ur']['rtb_lm_success']:.0%} succeeded); ratio to spar-py UR5 batch "
              f"{r['ur']['rtb_lm_over_batch']:.0f}x")
    m = r["numeric"]
    print(f"numeric (PUMA d5=95): {m['batch_us']:9.1f} us/pose  ({m['solutions_per_pose']:.1f} solutions/pose, "
          f"{m['solved']:.0%} solved, own q found {m['own_found']:.0%}; n = {m['n']})")
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

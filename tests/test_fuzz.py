"""The project's own fuzzer (issue 13 item 9): its mutations, its judge, a seeded sample of the
paper's cell, and the full run behind ``SPAR_FUZZ_FULL=1`` (see tests/fuzz/README.md)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import yaml

from fuzz import kbfuzz  # tests/ is on sys.path (pytest's rootdir-relative imports)

SEED = 13  #: the sample's seed (the issue's number): change it and the sample changes
SAMPLE_COUNT = 50  #: mutants per paper file in the sample (200 mutants, 350 runs, about 75 s on 2 cores)
SAMPLE_TIMEOUT = 3.0
FULL = os.environ.get("SPAR_FUZZ_FULL") == "1"


def sample_jobs() -> int:
    """Processes for the sample: every core, or this pytest-xdist worker's share of them (the
    other workers fill the rest; more would only queue, and the judge times every run)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return max(1, (os.cpu_count() or 1) // workers)


# ---------------------------------------------------------------------- the mutations


def test_mutants_are_deterministic_from_the_seed() -> None:
    a = kbfuzz.mutants(kbfuzz.PAPER_PROBLEM, SEED, 30)
    b = kbfuzz.mutants(kbfuzz.PAPER_PROBLEM, SEED, 30)
    c = kbfuzz.mutants(kbfuzz.PAPER_PROBLEM, SEED + 1, 30)
    assert a == b
    assert [m.data for m in a] != [m.data for m in c]


@pytest.mark.parametrize("source", kbfuzz.kb_files())
def test_every_operation_changes_every_file(source: str) -> None:
    original = (kbfuzz.KB / source).read_bytes()
    ms = kbfuzz.mutants(source, SEED, len(kbfuzz.OPS))
    assert {m.op for m in ms} == set(kbfuzz.OPS)
    assert all(m.data != original for m in ms)
    assert len({m.data for m in ms}) == len(ms)


@pytest.mark.parametrize("source", kbfuzz.kb_files())
def test_render_round_trips(source: str) -> None:
    tree = yaml.safe_load((kbfuzz.KB / source).read_text())
    assert yaml.safe_load(kbfuzz.render(tree)) == tree


def test_special_values_are_written_as_yaml_reads_them() -> None:
    tree = {"a": [float("nan"), float("inf"), -1e308, 10**400], "name": "init_pos1\n"}
    back = yaml.safe_load(kbfuzz.render(tree))
    assert back["a"][0] != back["a"][0] and back["a"][1:] == [float("inf"), -1e308, 10**400]
    assert back["name"] == "init_pos1\n"


def test_duplicate_key_is_written_twice() -> None:
    m = next(m for m in kbfuzz.mutants(kbfuzz.PAPER_PROBLEM, SEED, 60) if m.op == "duplicate_key")
    dup = [n for n in composed_mappings(yaml.compose(m.data.decode()))
           if len({k.value for k, _ in n.value}) < len(n.value)]
    assert dup, m.where


def composed_mappings(node: yaml.Node) -> list[yaml.MappingNode]:
    """Every mapping node of a composed YAML document."""
    if isinstance(node, yaml.MappingNode):
        return [node] + [m for _, v in node.value for m in composed_mappings(v)]
    if isinstance(node, yaml.SequenceNode):
        return [m for v in node.value for m in composed_mappings(v)]
    return []


def test_typo_key_keeps_the_order() -> None:
    tree = {"problem": "p", "units": {"length": "in"}, "goals": []}
    out, where = kbfuzz.typo_key(tree, kbfuzz.random.Random(1))
    assert len(out) == 3 and "->" in where


def test_model_mutants_are_checked_and_planned_with_a_user() -> None:
    assert kbfuzz.commands_for("objects/peg.yaml", 3) == [
        ("kb", "check", "objects/peg.yaml"), ("plan", "problems/peg_in_block.yaml", "--timeout", "3")]
    assert kbfuzz.commands_for("objects/peg2.yaml", 3)[1][1] == "problems/two_pegs.yaml"
    assert kbfuzz.commands_for("problems/regrasp.yaml", 2.5) == [("plan", "problems/regrasp.yaml", "--timeout", "2.5")]


# ---------------------------------------------------------------------- the judge

JUDGED = [
    # (exit, stderr, seconds, rss MB) -> finding with --timeout 3
    ((0, "", 0.5, 60), None),
    ((1, "", 0.5, 60), None),
    ((2, "spar: f.yaml: goals: a list, not 3\n", 0.4, 40), None),
    ((4, "spar: timeout: p: no result within 3 s\n", 3.3, 80), None),
    ((2, "", 0.4, 40), "no message"),
    ((4, "", 3.2, 40), "no message"),
    ((2, "spar: f.yaml: robot: a file (no file\n.yaml)\n", 0.4, 40), "multi-line stderr"),
    ((0, "x.py:1: RuntimeWarning: overflow\n  y = a * b\n", 0.4, 40), "multi-line stderr"),
    ((3, "spar: prolog: Python 'ValueError':\n", 0.4, 40), "exit 3"),
    ((2, "spar: prolog: Python 'ValueError':\n", 0.4, 40), "empty message"),
    ((1, "Traceback (most recent call last):\n  ...\nOverflowError: x\n", 0.4, 40), "traceback"),
    ((5, "spar: what\n", 0.4, 40), "exit 5"),
    ((-9, "", 1.0, 40), "killed by SIGKILL"),
    ((4, "spar: timeout\n", 6.5, 40), "past 2x the timeout"),
    ((0, "", 1.0, 1500), "RSS over 1024 MB"),
]


@pytest.mark.parametrize(("run", "finding"), JUDGED)
def test_classify(run: tuple[int, str, float, float], finding: str | None) -> None:
    assert kbfuzz.classify(*run, timeout=3.0) == finding


def test_execute_kills_at_the_cap(tmp_path: Path) -> None:
    code, _, seconds, _ = kbfuzz.execute([sys.executable, "-c", "import time; time.sleep(30)"], tmp_path, 0.5)
    assert code == -9 and seconds < 2.0


def test_execute_measures_peak_rss(tmp_path: Path) -> None:
    code, _, _, rss = kbfuzz.execute([sys.executable, "-c", "b = b'x' * (300 * 2**20)"], tmp_path, 20)
    assert code == 0 and rss > 290


def test_execute_limits_the_address_space(tmp_path: Path) -> None:
    code, err, _, rss = kbfuzz.execute([sys.executable, "-c", "b = b'x' * (2 * 2**30)"], tmp_path, 20)
    assert code == 1 and "MemoryError" in err and rss < 1024


@pytest.mark.parametrize("source", kbfuzz.PAPER_FILES)
def test_unmutated_paper_files_plan(source: str) -> None:
    """The fuzzer's own control: the paper's files as the fuzzer writes them plan (exit 0, OK)."""
    tree = yaml.safe_load((kbfuzz.KB / source).read_text())
    control = kbfuzz.Mutant(source, -1, "none", "", kbfuzz.render(tree))
    runs = kbfuzz.run_mutant((control, 10.0))
    assert [(r.code, r.finding) for r in runs] == [(0, None)] * len(runs), runs


# ---------------------------------------------------------------------- the sample


@pytest.fixture(scope="module")
def sample() -> kbfuzz.Report:
    """The seeded sample: SAMPLE_COUNT mutants of each of the paper's files (the same mutants
    and commands whatever the number of processes)."""
    return kbfuzz.fuzz(SEED, SAMPLE_COUNT, SAMPLE_TIMEOUT, kbfuzz.PAPER_FILES, jobs=sample_jobs())


@pytest.mark.slow
def test_sample_summary(sample: kbfuzz.Report, capsys: pytest.CaptureFixture[str]) -> None:
    with capsys.disabled():
        print("\n" + sample.summary())
    assert sample.mutants == SAMPLE_COUNT * len(kbfuzz.PAPER_FILES)
    assert {r.op for r in sample.runs} == set(kbfuzz.OPS)
    assert sum(sample.outcomes().values()) == len(sample.runs) == SAMPLE_COUNT * (1 + 2 * 3)


def findings(report: kbfuzz.Report, kinds: tuple[str, ...]) -> list[str]:
    """The findings of the given kinds, one line each, for an assertion's message."""
    return [f"{r.mutant} {r.op} at {r.where}: spar {r.command}: {r.outcome}: {kbfuzz.first_line(r.stderr)}"
            for r in report.findings() if r.finding and r.finding.startswith(kinds)]


@pytest.mark.slow
def test_sample_no_traceback(sample: kbfuzz.Report) -> None:
    assert findings(sample, ("traceback",)) == []


@pytest.mark.slow
def test_sample_no_internal_error(sample: kbfuzz.Report) -> None:
    assert findings(sample, ("exit 3", "exit ", "killed")) == []


@pytest.mark.slow
def test_sample_one_line(sample: kbfuzz.Report) -> None:
    assert findings(sample, ("no message", "empty message", "multi-line")) == []


@pytest.mark.slow
def test_sample_time_and_memory(sample: kbfuzz.Report) -> None:
    assert findings(sample, ("past", "RSS")) == []


@pytest.mark.slow
def test_sample_refuses_duplicate_and_unknown_keys(sample: kbfuzz.Report) -> None:
    assert [f"{r.mutant} {r.op} at {r.where}: spar {r.command}: exit {r.code}" for r in sample.accepted()] == []


# ---------------------------------------------------------------------- the full run


@pytest.mark.fuzz_full
@pytest.mark.skipif(not FULL, reason="the full fuzz run: SPAR_FUZZ_FULL=1 (make fuzz-full)")
def test_full_fuzz(capsys: pytest.CaptureFixture[str]) -> None:
    """Every kb file, SPAR_FUZZ_COUNT mutants each (200: 3,200 mutants), no finding."""
    count = int(os.environ.get("SPAR_FUZZ_COUNT", "200"))
    seed = int(os.environ.get("SPAR_FUZZ_SEED", str(SEED)))
    report = kbfuzz.fuzz(seed, count, SAMPLE_TIMEOUT, None, jobs=int(os.environ.get("SPAR_FUZZ_JOBS", "2")))
    with capsys.disabled():
        print("\n" + report.summary())
    if os.environ.get("SPAR_FUZZ_SAVE"):
        kbfuzz.save_findings(report, Path(os.environ["SPAR_FUZZ_SAVE"]), seed, count)
    assert findings(report, ("",)) == []


# ---------------------------------------------------------------------- the corpus

CORPUS = sorted((Path(__file__).parent / "fuzz" / "corpus").glob("*.yaml"))
CORPUS_SECONDS = 2.0  #: a bad cell is refused within this
CORPUS_RSS_MB = 1024.0


def header(path: Path) -> dict[str, str]:
    """The ``# key: value`` lines at the top of a corpus cell (expect-exit, mentions, xfail)."""
    out = {}
    for line in path.read_text().splitlines():
        if not line.startswith("# "):
            break
        key, _, value = line[2:].partition(": ")
        out[key] = value
    return out


def corpus_params(command: str) -> list:
    """One test per corpus cell, strict xfail where its header names the fix that is under way."""
    params = []
    for p in CORPUS:
        xfail = header(p).get("xfail")
        marks = [pytest.mark.xfail(strict=True, reason=xfail)] if xfail else []
        params.append(pytest.param(command, p, id=f"{command.replace(' ', '_')}-{p.stem}", marks=marks))
    return params


def test_corpus_headers() -> None:
    assert len(CORPUS) >= 10
    for p in CORPUS:
        h = header(p)
        assert h.get("expect-exit") == "2" and h.get("mentions"), p.name


@pytest.mark.parametrize(("command", "path"), corpus_params("plan") + corpus_params("kb check"))
def test_corpus_cell_is_refused(command: str, path: Path) -> None:
    """A physically impossible or unusable cell: exit 2, one line naming the parties, in 2 s and 1 GB."""
    h = header(path)
    args = ["plan", str(path), "--timeout", "5"] if command == "plan" else ["kb", "check", str(path)]
    code, err, seconds, rss = kbfuzz.execute(kbfuzz.spar(args), kbfuzz.ROOT, CORPUS_SECONDS + 1.0)
    lines = err.strip().splitlines()
    assert (code, len(lines)) == (int(h["expect-exit"]), 1), err
    assert all(name in lines[0] for name in h["mentions"].split(", ")), lines[0]
    assert seconds <= CORPUS_SECONDS and rss < CORPUS_RSS_MB, (seconds, rss)

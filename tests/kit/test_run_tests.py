"""The suite's own scripts, as a contributor meets them: tools/run-tests (`make test`, `make test-quick`) and
tools/keep-durations. Each runs on a repository of its own here (a copy of the script beside a small suite), so
the run of the suite that runs these tests keeps its artifacts."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SUITE = {
    "pytest.ini": "[pytest]\nmarkers =\n    serial: real time\n    system: Docker\n",
    "tests/test_small.py": "import pytest\n\ndef test_quick():\n    pass\n\n@pytest.mark.serial\ndef test_on_the_clock():\n    pass\n",
}


def small_repository(tmp_path: Path) -> Path:
    repo = tmp_path / "repo"
    (repo / "tools").mkdir(parents=True)
    shutil.copy2(ROOT / "tools" / "run-tests", repo / "tools" / "run-tests")
    for name, text in SUITE.items():
        (repo / name).parent.mkdir(parents=True, exist_ok=True)
        (repo / name).write_text(text)
    return repo


def run_tests(repo: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["tools/run-tests", "", *args], cwd=repo, capture_output=True, text=True, timeout=300,
                          env={"PATH": "/usr/bin:/bin", "PY": sys.executable, "TEST_WORKERS": "0"})


def test_a_k_that_matches_no_test_ends_with_exit_5_and_says_so(tmp_path):
    repo = small_repository(tmp_path)
    r = run_tests(repo, "-k", "no_such_test_name")
    assert r.returncode == 5, r.stdout + r.stderr
    assert "run-tests: no test was selected (PYTEST_ARGS: -k no_such_test_name); nothing ran" in r.stderr


def test_a_run_that_selects_tests_in_one_part_only_passes(tmp_path):
    repo = small_repository(tmp_path)
    for k, parts in (("quick", 1), ("on_the_clock", 1), ("test_", 2)):   # each part passes its one test
        r = run_tests(repo, "-k", k)
        assert r.returncode == 0, (k, r.stdout + r.stderr)
        assert r.stdout.count("1 passed") == parts, (k, r.stdout)


def test_a_bad_option_is_pytests_usage_error_and_a_failure_fails(tmp_path):
    repo = small_repository(tmp_path)
    r = run_tests(repo, "--bogus-option")
    assert r.returncode == 4 and "unrecognized arguments: --bogus-option" in r.stdout + r.stderr
    (repo / "tests" / "test_small.py").write_text(SUITE["tests/test_small.py"] + "\ndef test_broken():\n    assert 0\n")
    assert run_tests(repo).returncode == 1


def test_a_run_sets_the_last_runs_durations_aside(tmp_path):
    repo = small_repository(tmp_path)
    (repo / "artifacts").mkdir()
    (repo / "artifacts" / "test-durations.txt").write_text("# the run before\n")
    assert run_tests(repo, "-k", "on_the_clock").returncode == 0
    assert (repo / "artifacts" / "test-durations.previous.txt").read_text() == "# the run before\n"
    # this small suite writes no durations of its own (tests/conftest.py does): the last run's are not left as this one's
    assert not (repo / "artifacts" / "test-durations.txt").exists()


# --- tools/keep-durations ----------------------------------------------------------------------------

def durations(parallel: str, serial: str | None, *, exit_parallel=0, exit_serial=0) -> str:
    text = (f"# pytest -q -n 2 --dist loadgroup --no-loadscope-reorder -m {parallel}\n"
            f"# 2026-11-30 08:08:17 UTC: 1521.9 s wall, exit {exit_parallel}, 4505 passed, 2 workers\n"
            "# seconds phase test\n261.53s call     tests/system/test_hub.py::test_hub_week_of_a_class@docker-engine\n"
            "0.20s call     tests/kit/test_model.py::test_short\n")
    if serial is not None:
        text += (f"# pytest -q -m {serial}\n# 2026-11-30 08:08:17 UTC: 1206.0 s wall, exit {exit_serial}, 444 passed\n"
                 "# seconds phase test\n98.20s call     tests/lessons/test_no_solution.py::test_x[07_real_robot]\n")
    return text


def keep(tmp_path: Path, text: str) -> tuple[subprocess.CompletedProcess, Path]:
    source, kept = tmp_path / "test-durations.txt", tmp_path / "durations.txt"
    source.write_text(text)
    kept.write_text("# the kept ones\n")
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "keep-durations"), str(source), str(kept)],
                       capture_output=True, text=True, timeout=60)
    return r, kept


@pytest.mark.parametrize("text, kept_tests", [
    (durations("not serial", "serial"), ["tests/system/test_hub.py::test_hub_week_of_a_class",
                                          "tests/lessons/test_no_solution.py::test_x[07_real_robot]"]),
])
def test_keep_durations_writes_a_whole_passing_run_longest_first(tmp_path, text, kept_tests):
    r, kept = keep(tmp_path, text)
    assert r.returncode == 0, r.stderr
    assert [line.split()[-1] for line in kept.read_text().splitlines() if not line.startswith("#")] == kept_tests
    assert "keep-durations: 2 tests of 3" in r.stdout


@pytest.mark.parametrize("text", [
    durations("(not system) and (not serial)", "(not system) and (serial)"),   # make test-quick
    durations("not serial", "serial", exit_parallel=1),                          # a run that failed
    durations("not serial", None),                                               # one part
    durations("not serial", "serial").replace("--no-loadscope-reorder", "--no-loadscope-reorder -k sweep"),
    "# pytest tests/grader/test_grader_slips.py\n# 2026-11-30 09:50:33 UTC: 32.1 s wall, exit 0, 34 passed\n"
    "# seconds phase test\n2.00s call     tests/grader/test_grader_slips.py::test_a\n",   # one file
], ids=["test-quick", "failed", "one part", "-k", "one file"])
def test_keep_durations_refuses_another_runs_file_and_keeps_the_kept_ones(tmp_path, text):
    r, kept = keep(tmp_path, text)
    assert r.returncode == 1 and "is not a whole `make test` that passed" in r.stderr, r.stderr
    assert kept.read_text() == "# the kept ones\n"

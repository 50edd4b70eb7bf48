"""tests/fuzz/run.py's report of a finding: what a CI machine's output must carry, since its
work folder (logs and artifacts) is gone once the run ends."""

import base64
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))

import run as fuzz_run  # noqa: E402

LOG = """INFO: Seed: 123
#256\tpulse  cov: 180 ft: 334 corp: 43/530b lim: 54 exec/s: 64 rss: 79Mb

=== Uncaught Python exception: ===
ValueError: cannot reshape array of size 3 into shape (2,)
Traceback (most recent call last):
  File "tests/fuzz/dataflash_fuzz.py", line 120, in test_one_input
==1234== ERROR: libFuzzer: fuzz target exited
MS: 2 ChangeByte-InsertByte-; base unit: 0
artifact_prefix='x/'; Test unit written to x/crash-abc
"""


def failed_result(tmp_path, artifact: bytes, name="crash-abc"):
    work = fuzz_run.Work(tmp_path)
    target = fuzz_run.BY_NAME["dataflash"]
    work.artifacts(target.name).mkdir(parents=True)
    (work.root / "logs").mkdir()
    log = work.log(target.name)
    log.write_text(LOG)
    (work.artifacts(target.name) / name).write_bytes(artifact)
    result = fuzz_run.Result(target, error="exited 77 before its time was up", log=log, runs=1,
                             artifacts={"crash": 1}, reports=1, new_artifacts=[name])
    return result, work


def test_a_finding_prints_the_exception_and_the_input_that_made_it(tmp_path):
    crash = bytes(range(40))
    result, work = failed_result(tmp_path, crash)
    lines = fuzz_run.finding(result, work)
    text = "\n".join(lines)
    assert lines[1] == "=== Uncaught Python exception: ==="       # from the finding on
    assert "ValueError: cannot reshape" in text and "INFO: Seed" not in text
    b64 = text.rsplit("base64 ", 1)[1].strip()
    assert base64.b64decode(b64) == crash


def test_a_large_artifact_is_named_but_not_printed(tmp_path):
    result, work = failed_result(tmp_path, b"\0" * (fuzz_run.ARTIFACT_SHOWN_BYTES + 1))
    last = fuzz_run.finding(result, work)[-1]
    assert last.endswith(f"{fuzz_run.ARTIFACT_SHOWN_BYTES + 1} bytes") and "base64" not in last


def test_a_target_that_found_nothing_prints_nothing_more(tmp_path):
    result, work = failed_result(tmp_path, b"x")
    result.error, result.artifacts, result.reports = None, {}, 0
    assert fuzz_run.finding(result, work) == []

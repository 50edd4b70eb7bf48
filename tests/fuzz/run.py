"""Run heliquad's fuzz targets for a while each and print what every one of them did.

Host targets are Python harnesses run under atheris (pip install atheris): tlog
(host/records/tlog.py), framer (sim/base/framing.py) and dataflash (identify's .BIN reading). Firmware targets are libFuzzer executables built
with clang from firmware/ with HQ_FUZZ=ON: sim_link (fuzz_sim_link), telemetry
(fuzz_telemetry) and usb_control (fuzz_usb_control, the Teensy 3.5 image's USB port). Every target runs as libFuzzer does, on its corpus folder with
-max_total_time; the result line gives executions, executions per second, coverage (cov: and
ft: of the last status line), corpus size, and what was found: crash-/timeout-/oom-/leak-
artifacts and sanitizer or libFuzzer error reports in the output.
"""

from __future__ import annotations

import argparse
import base64
import importlib
import importlib.util
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

FUZZ_DIR = Path(__file__).resolve().parent
REPO = FUZZ_DIR.parents[1]
FIRMWARE_TARGETS_PREFIX = "fuzz_"         # firmware target NAME builds the executable fuzz_NAME
HOST, FIRMWARE = "host", "firmware"
TIMEOUT_S = 10                            # libFuzzer -timeout: one input longer than this is a hang
GRACE_S = 120                             # start-up, instrumenting and final stats past the time
BUILD_TIMEOUT_S = 1800
PROGRESS_EVERY_S = 15
ERROR_LINE_LEN = 240
POLL_S = 0.5
ARTIFACT_KINDS = {"crash": "crashes", "timeout": "timeouts", "oom": "OOMs", "leak": "leaks"}
REPORT_MARKERS = ("ERROR: AddressSanitizer", "ERROR: LeakSanitizer", "runtime error:",
                  "ERROR: libFuzzer")
FINDING_MARKERS = ("=== Uncaught Python exception", "Traceback (most recent call last)") \
    + REPORT_MARKERS
FINDING_LINES = 40                        # of a failed target's log, printed with the results
ARTIFACT_SHOWN_BYTES = 4096               # a finding's input this small is printed (base64)
STATUS = re.compile(r"^#(\d+)\s+\w+\s+cov: (\d+) ft: (\d+) corp: ", re.M)
STAT = re.compile(r"^stat::(\w+):\s+(\d+)", re.M)
DONE = re.compile(r"^Done (\d+) runs in (\d+) second", re.M)


@dataclass(frozen=True)
class Target:
    name: str
    kind: str
    about: str

    @property
    def executable(self) -> str:
        return FIRMWARE_TARGETS_PREFIX + self.name


TARGETS = (
    Target("tlog", HOST, "host/records/tlog.py read_tlog on .tlog files (tests/fuzz/tlog_fuzz.py)"),
    Target("framer", HOST, "sim/base/framing.py Framer and Codec on link byte streams "
                           "(tests/fuzz/framer_fuzz.py)"),
    Target("dataflash", HOST, "identify's .BIN reading, heliquad's and ArduPilot SystemID logs "
                              "(tests/fuzz/dataflash_fuzz.py)"),
    Target("sim_link", FIRMWARE, "firmware sim link, executable fuzz_sim_link"),
    Target("telemetry", FIRMWARE, "firmware telemetry link, executable fuzz_telemetry"),
    Target("usb_control", FIRMWARE, "Teensy 3.5 image's USB port (TinyUSB and its port layer), "
                                     "executable fuzz_usb_control"),
)
BY_NAME = {t.name: t for t in TARGETS}


@dataclass
class Result:
    target: Target
    error: str | None = None              # why it did not run, or did not run to the end
    log: Path | None = None
    seconds: float = 0.0
    runs: int | None = None
    exec_per_s: int | None = None
    cov: int | None = None
    ft: int | None = None
    corpus: int = 0
    artifacts: dict = field(default_factory=dict)
    reports: int = 0
    new_artifacts: list = field(default_factory=list)     # their names, in the artifacts folder

    @property
    def found(self) -> int:
        return sum(self.artifacts.values()) + self.reports

    @property
    def ok(self) -> bool:
        return self.error is None and not self.found

    def line(self) -> str:
        name = f"{self.target.name:<10}"
        if self.error and self.runs is None:
            return f"{name} NOT RUN: {self.error}"
        figures = (f"{_n(self.runs)} execs, {_n(self.exec_per_s)} exec/s, cov {_n(self.cov)}, "
                   f"ft {_n(self.ft)}, corpus {self.corpus}, "
                   + ", ".join(f"{label} {self.artifacts.get(kind, 0)}"
                               for kind, label in ARTIFACT_KINDS.items())
                   + f", error reports {self.reports}")
        verdict = "ok" if self.ok else "FAILED: " + (self.error or "findings, see log")
        return f"{name} {self.seconds:5.0f} s  {figures}  {verdict}  (log {self.log})"


def _n(value) -> str:
    return "-" if value is None else str(value)


@dataclass
class Work:
    """The work folder: corpus/NAME, artifacts/NAME, logs, build."""
    root: Path

    def corpus(self, name: str) -> Path:
        return self.root / "corpus" / name

    def artifacts(self, name: str) -> Path:
        return self.root / "artifacts" / name

    def log(self, name: str) -> Path:
        return self.root / "logs" / f"{name}.log"

    @property
    def build(self) -> Path:
        return self.root / "build"


def seed_module_name(target: Target) -> str | None:
    """The module in tests/fuzz whose seed_inputs() seeds the target: a host target's harness
    (NAME_fuzz), a firmware target's NAME_seeds if it has one; None if it has none."""
    name = f"{target.name}_fuzz" if target.kind == HOST else f"{target.name}_seeds"
    return name if (FUZZ_DIR / f"{name}.py").is_file() else None


def seed_corpus(target: Target, folder: Path) -> int:
    """Write the target's seed inputs into ``folder``; how many."""
    if str(FUZZ_DIR) not in sys.path:
        sys.path.insert(0, str(FUZZ_DIR))
    module = seed_module_name(target)
    if module is None:
        return 0
    seeds = importlib.import_module(module).seed_inputs()
    for label, data in seeds.items():
        (folder / f"seed-{label}").write_bytes(data)
    return len(seeds)


def _first_error(log: Path) -> str:
    """The first line of a build log that looks like the reason it failed; with CMake's
    "CMake Error at ...:" also the explanation on the line after it."""
    lines = [line.strip() for line in log.read_text(errors="replace").splitlines() if line.strip()]
    for i, line in enumerate(lines):
        if re.search(r"error|No rule to make target|not found", line, re.I):
            if line.startswith("CMake Error") and i + 1 < len(lines):
                line += " " + lines[i + 1]
            return line[:ERROR_LINE_LEN]
    return "no error line in the log"


def build_firmware(targets: list, work: Work) -> str | None:
    """Configure and build the firmware fuzz executables; None, or why it failed."""
    if shutil.which("clang++") is None:
        return "clang++ is not on PATH (the firmware targets need clang with libFuzzer)"
    log = work.log("build")
    if shutil.which("clang") is None:
        return "clang is not on PATH (fuzz_usb_control compiles TinyUSB's C with it)"
    configure = ["cmake", "-S", str(REPO / "firmware"), "-B", str(work.build),
                 "-DCMAKE_CXX_COMPILER=clang++", "-DCMAKE_C_COMPILER=clang", "-DHQ_FUZZ=ON",
                 "-DCMAKE_BUILD_TYPE=RelWithDebInfo", f"-DPython3_EXECUTABLE={sys.executable}"]
    build = ["cmake", "--build", str(work.build), "--target",
             *(t.executable for t in targets), "-j2"]
    print(f"building {', '.join(t.executable for t in targets)} (log {log})", flush=True)
    with open(log, "w") as fh:
        for step, cmd in (("cmake configure", configure), ("cmake --build", build)):
            fh.write("$ " + " ".join(cmd) + "\n")
            fh.flush()
            try:
                rc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT,
                                    timeout=BUILD_TIMEOUT_S).returncode
            except subprocess.TimeoutExpired:
                return f"{step} took over {BUILD_TIMEOUT_S} s; log {log}"
            if rc != 0:
                return (f"firmware fuzz build failed, {step} exited {rc}: {_first_error(log)} "
                        f"(log {log})")
    missing = [str(work.build / t.executable) for t in targets
               if not (work.build / t.executable).is_file()]
    if missing:
        return f"the build succeeded but did not make {', '.join(missing)} (log {log})"
    return None


def command(target: Target, work: Work, seconds: int) -> list:
    artifacts = work.artifacts(target.name)
    flags = [str(work.corpus(target.name)), f"-max_total_time={seconds}", "-print_final_stats=1",
             f"-artifact_prefix={artifacts}{os.sep}", f"-timeout={TIMEOUT_S}"]
    if target.kind == HOST:
        return [sys.executable, str(FUZZ_DIR / f"{target.name}_fuzz.py"), *flags]
    return [str(work.build / target.executable), *flags]


def prepare(target: Target, work: Work) -> str | None:
    """Folders and seed corpus for one target; None, or why it cannot run."""
    for folder in (work.corpus(target.name), work.artifacts(target.name)):
        folder.mkdir(parents=True, exist_ok=True)
    if target.kind == HOST and importlib.util.find_spec("atheris") is None:
        return f"atheris is not installed for {sys.executable} (pip install atheris)"
    try:
        seed_corpus(target, work.corpus(target.name))
    except Exception as exc:              # noqa: BLE001 - a broken harness is reported, not raised
        return f"its harness does not import or seed: {type(exc).__name__}: {exc}"
    return None


class Run:
    """One fuzz target running in its own process group, its output in a log file."""

    def __init__(self, target: Target, work: Work, seconds: int):
        self.result = Result(target, log=work.log(target.name))
        self.work, self.seconds = work, seconds
        folder = work.artifacts(target.name)
        self.before = set(os.listdir(folder))
        self.started = time.monotonic()
        self.last_progress = self.started
        with open(self.result.log, "w") as fh:
            self.proc = subprocess.Popen(command(target, work, seconds), stdout=fh,
                                         stderr=subprocess.STDOUT, cwd=self.work.root,
                                         start_new_session=True)

    def elapsed(self) -> float:
        return time.monotonic() - self.started

    def overdue(self) -> bool:
        return self.elapsed() > self.seconds + GRACE_S

    def stop(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()

    def progress(self) -> str | None:
        """A progress line every PROGRESS_EVERY_S, from the log's last status line."""
        if time.monotonic() - self.last_progress < PROGRESS_EVERY_S:
            return None
        self.last_progress = time.monotonic()
        status = STATUS.findall(_tail(self.result.log))
        figures = (f"#{status[-1][0]} cov {status[-1][1]} ft {status[-1][2]}" if status
                   else "starting")
        return f"  {self.result.target.name}: {self.elapsed():.0f}/{self.seconds} s, {figures}"

    def finish(self, rc: int) -> Result:
        r = self.result
        r.seconds = self.elapsed()
        text = r.log.read_text(errors="replace")
        stats = dict(STAT.findall(text))
        status = STATUS.findall(text)
        done = DONE.search(text)
        if "number_of_executed_units" in stats:
            r.runs = int(stats["number_of_executed_units"])
        elif done:
            r.runs = int(done.group(1))
        if "average_exec_per_sec" in stats:
            r.exec_per_s = int(stats["average_exec_per_sec"])
        if status:
            r.cov, r.ft = int(status[-1][1]), int(status[-1][2])
        folder = self.work.artifacts(r.target.name)
        new = set(os.listdir(folder)) - self.before
        r.new_artifacts = sorted(new)
        r.artifacts = {kind: sum(n.startswith(kind + "-") for n in new) for kind in ARTIFACT_KINDS}
        r.reports = sum(text.count(marker) for marker in REPORT_MARKERS)
        r.corpus = len(os.listdir(self.work.corpus(r.target.name)))
        if r.error is None and (rc != 0 or not done):
            r.error = (f"exited {rc} before its time was up" if rc != 0 else
                       "ended without libFuzzer's 'Done' line")
        if r.runs is None:
            r.runs = 0
        return r


def finding(result: Result, work: Work) -> list:
    """What a failed target's log says about its finding (from the first report or traceback,
    at most FINDING_LINES lines) and its new artifacts, the small ones in base64: the work
    folder of a CI machine is gone once its output is read."""
    if result.ok or result.log is None or not result.log.is_file():
        return []
    lines = result.log.read_text(errors="replace").splitlines()
    start = next((i for i, line in enumerate(lines)
                  if any(marker in line for marker in FINDING_MARKERS)), None)
    shown = lines[start:start + FINDING_LINES] if start is not None else lines[-FINDING_LINES:]
    out = [f"-- {result.target.name}: its log from the finding on --"] + shown
    folder = work.artifacts(result.target.name)
    for name in result.new_artifacts:
        data = (folder / name).read_bytes()
        out.append(f"-- artifact {folder / name}: {len(data)} bytes"
                   + (f", base64 {base64.b64encode(data).decode()}"
                      if len(data) <= ARTIFACT_SHOWN_BYTES else ""))
    return out


def _tail(path: Path, size: int = 8192) -> str:
    with open(path, "rb") as fh:
        fh.seek(max(0, os.path.getsize(path) - size))
        return fh.read().decode(errors="replace")


def run_all(targets: list, work: Work, seconds: int, jobs: int) -> list:
    """Run the targets, ``jobs`` at a time, printing progress; their results in order."""
    results, queue, running = {}, list(targets), []
    try:
        while queue or running:
            while queue and len(running) < jobs:
                target = queue.pop(0)
                run = Run(target, work, seconds)
                print(f"running {target.name} for {seconds} s (log {run.result.log})", flush=True)
                running.append(run)
            time.sleep(POLL_S)
            for run in list(running):
                rc = run.proc.poll()
                if rc is None and run.overdue():
                    run.stop()
                    run.result.error = f"still running {GRACE_S} s past its time; killed"
                    rc = run.proc.returncode
                if rc is None:
                    line = run.progress()
                    if line:
                        print(line, flush=True)
                    continue
                running.remove(run)
                result = run.finish(rc)
                results[result.target.name] = result
                print(f"finished {result.target.name}", flush=True)
    finally:
        for run in running:
            run.stop()
    return [results[t.name] for t in targets]


def parse_args(argv: list) -> argparse.Namespace:
    names = ", ".join(t.name for t in TARGETS)
    parser = argparse.ArgumentParser(
        prog="run.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=f"""targets: {names} (--list describes them)

example:
  python tests/fuzz/run.py --seconds 60 --target tlog --target framer --work /tmp/hq-fuzz

Seed corpora are generated into WORK/corpus/NAME (host targets: valid packets and .tlog files
made with the dialect's Codec; usb_control: a Linux enumeration and both 134-baud requests,
tests/fuzz/usb_control_seeds.py; the other firmware targets: empty), artifacts go to WORK/artifacts/NAME,
libFuzzer's output to WORK/logs/NAME.log. Every target runs with -timeout={TIMEOUT_S}: an
input taking longer is a hang. The firmware targets are built first, in WORK/build, with
clang and clang++ and -DHQ_FUZZ=ON; if that fails they are reported as not run.
Exit status 0 only if every requested target ran for its time and found nothing, else 1.""")
    parser.add_argument("--seconds", type=int, default=60, metavar="N",
                        help="fuzzing time per target (default 60)")
    parser.add_argument("--target", action="append", choices=list(BY_NAME), metavar="NAME",
                        help="a target to run; repeat for several (default all)")
    parser.add_argument("--work", type=Path, metavar="DIR",
                        help="work folder, kept (corpora grow from run to run); default a new "
                             "folder in the system temp dir")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="targets fuzzed at the same time (default 1)")
    parser.add_argument("--list", action="store_true", help="list the targets and exit")
    args = parser.parse_args(argv)
    if args.seconds < 1 or args.jobs < 1:
        parser.error("--seconds and --jobs must be at least 1")
    return args


def main(argv: list | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.list:
        for t in TARGETS:
            print(f"{t.name:<10} {t.kind:<8} {t.about}")
        return 0
    targets = [BY_NAME[n] for n in dict.fromkeys(args.target)] if args.target else list(TARGETS)
    work = Work((args.work or Path(tempfile.mkdtemp(prefix="heliquad-fuzz-"))).resolve())
    (work.root / "logs").mkdir(parents=True, exist_ok=True)
    print(f"work folder {work.root}", flush=True)

    failed = {t.name: prepare(t, work) for t in targets}
    firmware = [t for t in targets if t.kind == FIRMWARE and failed[t.name] is None]
    if firmware:
        error = build_firmware(firmware, work)
        failed.update({t.name: error for t in firmware})
    ready = [t for t in targets if failed[t.name] is None]
    try:
        ran = {r.target.name: r for r in run_all(ready, work, args.seconds, args.jobs)}
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130

    print("\nresults:")
    results = [ran.get(t.name) or Result(t, error=failed[t.name]) for t in targets]
    for r in results:
        print(r.line())
    for r in results:
        for line in finding(r, work):
            print(line)
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())

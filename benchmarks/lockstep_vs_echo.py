"""Benchmark: lockstep frames per second against a raw pty echo round trip, same run.

Baseline (the issue's): a minimal echo over a pty. A 25-line C program (compiled here with
the system's cc) owns a pty master and writes back every byte it reads; the client writes one
frame of the sim link's size (HQ_SENSOR_FRAME, 210 bytes) with pyserial and reads it back.
This is the transport's round-trip cost with nothing else in it, for a Python simulator.

Floor, for reference: the same echo with a C client (write, poll, read), the round trip the
C++ engine (heliquad._simcore's sim/rig/rig_engine.cpp) could reach if the firmware took no
time and sent no telemetry.

Lockstep: ``heliquad sil`` with the transfer-function plant (the paper's roll model) at a
200 Hz loop, mixer injection: plant step, sensor packet, frame out, firmware step, reply and
that step's telemetry in, logged. Frames per second over the lockstep loop (hover included).

The same with the 6-DoF vehicle on the roll rig (issue 4: target >= 0.5). Prints the rates,
the ratios and the real-time factors; --profile adds where a vehicle frame's time goes.

    python benchmarks/lockstep_vs_echo.py [--frames 10000] [--trials 5] [--profile]
"""

import argparse
import os
import pathlib
import statistics
import subprocess
import tempfile
import time

import serial

from heliquad.host.acquire.experiment import run_sil
from heliquad.sim.rig.setup import SilConfig

ECHO_C = r"""
#define _GNU_SOURCE
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>
int main(void) {
    int m = posix_openpt(O_RDWR | O_NOCTTY);
    if (m < 0 || grantpt(m) || unlockpt(m)) return 1;
    const char* name = ptsname(m);
    int s = open(name, O_RDWR | O_NOCTTY);          /* keep the line open, make it raw */
    struct termios t; tcgetattr(s, &t); cfmakeraw(&t); tcsetattr(s, TCSANOW, &t);
    printf("%s\n", name); fflush(stdout);
    unsigned char buf[4096];
    for (;;) {
        ssize_t n = read(m, buf, sizeof buf);
        if (n <= 0) return 0;
        for (ssize_t off = 0; off < n;) { ssize_t w = write(m, buf + off, n - off); if (w <= 0) return 0; off += w; }
    }
}
"""
CLIENT_C = r"""
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>
int main(int argc, char** argv) {
    int fd = open(argv[1], O_RDWR | O_NOCTTY), n = atoi(argv[2]), len = atoi(argv[3]);
    struct termios t; tcgetattr(fd, &t); cfmakeraw(&t); tcsetattr(fd, TCSANOW, &t);
    unsigned char out[4096], in[4096];
    for (int i = 0; i < len; ++i) out[i] = (unsigned char)i;
    struct timespec t0, t1;
    for (int k = -100; k < n; ++k) {                  /* 100 warm-up round trips */
        if (k == 0) clock_gettime(CLOCK_MONOTONIC, &t0);
        if (write(fd, out, len) != len) return 1;
        for (int got = 0; got < len;) {
            struct pollfd p = {fd, POLLIN, 0};
            if (poll(&p, 1, 1000) <= 0) return 2;
            ssize_t r = read(fd, in, sizeof in);
            if (r <= 0) return 3;
            got += (int)r;
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("%f\n", n / ((t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec)));
    return 0;
}
"""
FRAME_BYTES = 210


def _compile(tmp, name, source):
    src, exe = pathlib.Path(tmp, name + ".c"), pathlib.Path(tmp, name)
    src.write_text(source)
    subprocess.run(["cc", "-O2", "-o", str(exe), str(src)], check=True)
    return str(exe)


def echo_round_trips(frames: int) -> tuple[float, float]:
    """Round trips per second of the pty echo: (pyserial client, C client)."""
    with tempfile.TemporaryDirectory() as tmp:
        echo, client = _compile(tmp, "echo", ECHO_C), _compile(tmp, "client", CLIENT_C)
        proc = subprocess.Popen([echo], stdout=subprocess.PIPE, text=True)
        try:
            path = proc.stdout.readline().strip()
            port = serial.Serial(path, timeout=1.0)
            frame = bytes(range(FRAME_BYTES))
            for _ in range(100):                                   # warm up
                port.write(frame)
                port.read(FRAME_BYTES)
            t0 = time.perf_counter()
            for _ in range(frames):
                port.write(frame)
                got = port.read(FRAME_BYTES)
                assert len(got) == FRAME_BYTES
            python_rate = frames / (time.perf_counter() - t0)
            port.close()
            c_rate = float(subprocess.run([client, path, str(frames), str(FRAME_BYTES)],
                                          check=True, capture_output=True, text=True).stdout)
        finally:
            proc.kill()
            proc.wait()
    return python_rate, c_rate


def lockstep_frames(frames: int, plant: str = "tf"):
    cycles = max(1, int(round(frames / 200 * 2.0)))              # 2 Hz: 100 frames a cycle
    cfg = SilConfig(freq_hz=2.0, cycles=cycles, amplitude=0.05, plant=plant, rig="roll")
    with tempfile.TemporaryDirectory() as tmp:
        r = run_sil(cfg, os.path.join(tmp, "bench"), progress=lambda *_: None)
    return r


def profile_vehicle(frames: int) -> None:
    """Where a vehicle-plant frame's time goes: the top functions by own time."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    r = lockstep_frames(frames, "vehicle")
    prof.disable()
    stats = pstats.Stats(prof)
    rows = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:6]
    print(f"profile, vehicle plant ({r.frames} frames; times inflated by the profiler):")
    for (filename, line, name), (_, _, tottime, _, _) in rows:
        print(f"  {1e6 * tottime / r.frames:7.1f} us/frame  {name} ({os.path.basename(filename)}:{line})")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=10000)
    parser.add_argument("--trials", type=int, default=5,
                        help="trials of echo and lockstep, back to back; the median counts")
    parser.add_argument("--profile", action="store_true", help="also profile a vehicle-plant run")
    args = parser.parse_args()
    # The machine is shared: each trial times the echo and both plants back to back, so a
    # burst of load elsewhere lands on both sides of that trial's ratios; the figure that
    # counts is the median over the trials.
    rows = []
    for k in range(args.trials):
        echo, floor = echo_round_trips(args.frames)
        fps = {}
        for plant in ("tf", "vehicle"):
            r = lockstep_frames(args.frames, plant)
            fps[plant] = r.frames / r.loop_s
        rows.append((echo, floor, fps["tf"], fps["vehicle"]))
        print(f"trial {k + 1}: echo {echo:6.0f} (C client {floor:6.0f}) round trips/s; lockstep "
              f"tf {fps['tf']:6.0f}, vehicle {fps['vehicle']:6.0f} frames/s; ratios "
              f"{fps['tf'] / echo:.3f}, {fps['vehicle'] / echo:.3f}", flush=True)
    med = [statistics.median(col) for col in zip(*rows)]
    echo, floor = med[0], med[1]
    print(f"\nmedians over {args.trials} trials ({FRAME_BYTES}-byte echo frames, 200 Hz loop):")
    print(f"  raw pty echo, pyserial client: {echo:8.0f} round trips/s  (baseline)")
    print(f"  raw pty echo, C client:        {floor:8.0f} round trips/s  (floor)")
    for i, (plant, target) in enumerate((("tf", 0.6), ("vehicle", 0.5))):
        fps = med[2 + i]
        ratio = statistics.median(row[2 + i] / row[0] for row in rows)
        print(f"  lockstep, {plant:7s} plant:      {fps:8.0f} frames/s, ratio {ratio:.3f} "
              f"(target >= {target}), {fps / floor:.3f} of the floor, "
              f"{fps / 200.0:.0f}x real time")
    if args.profile:
        profile_vehicle(min(args.frames, 2000))


if __name__ == "__main__":
    main()

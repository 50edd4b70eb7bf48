// The most a host pseudo-terminal's backlog bound can be (PtySerial::bound_backlog, serial.hpp).
// A fact of the host's ptys, not of the core (the Teensy has none); in a header of its own so
// that the bindings give Python the same number (sim/base/firmware_facts.py).
#pragma once

#include <cstddef>

namespace hq {

// What the pty's line discipline holds in sight of TIOCINQ: Linux's N_TTY_BUF_SIZE (4096),
// less one.
constexpr size_t kMaxPtyBacklogBytes = 4095;

}  // namespace hq

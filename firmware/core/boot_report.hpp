// The boot report in words: what start-up found (LoopStatus::boot, loop_exchange.hpp) as one
// STATUSTEXT notice per finding, in order: why the chip reset, where the parameters came
// from, the IMU and its path, the SD card. init() raises the notices start-up always raised
// (a store that is empty, corrupt or holds a value out of range; the DMP's fallback; a
// missing IMU) in these words, and set_card_state() the card's when it cannot log; the link sends the whole report again, each finding's words after "boot: "
// (what was found at start-up, not what holds now), to a ground station it hears for the
// first time and on request (docs/link-contract.md).
#pragma once

#include "loop_exchange.hpp"

namespace hq {

constexpr int kBootFindings = 4;

// Finding i (0: the reset, 1: the parameters, 2: the IMU, 3: the SD card) of the report.
Notice boot_finding(const BootReport& report, int i);
// The SD card's state in words: at start-up (the report's finding) or when it changes in
// flight (logging stops or the card comes back: said once per change).
Notice card_notice(CardState s);
Notice params_notice(ParamsFinding f, int param_index, SetResult param_result);
Notice imu_notice(ImuFinding f, DmpStep step);
// The IMU's finding from its start-up's result and the path IMU_PATH asked for.
ImuFinding imu_finding(InitResult r, ImuPath path);
// Whether start-up announces the finding as it happens (the others wait for the report).
bool announced(ParamsFinding f);
bool announced(ImuFinding f);

}  // namespace hq

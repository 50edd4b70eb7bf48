// How long the loop's work takes, for HQ_FW_STATUS: the target measures each loop (cycles of
// its CPU cycle counter) and records it; once a second the firmware reports the median and
// the maximum of the loops recorded since the last report, and the overruns (ticks missed
// because a loop ran past its period). A target without a cycle counter (the host build)
// records nothing and the report carries zeros.
#pragma once

#include <cstdint>

namespace hq {

class LoopLoad {
public:
    static constexpr int kCapacity = 256;      // > one second of loops at 200 Hz

    void record(uint32_t cycles, uint32_t overruns_total) {
        if (count_ < kCapacity) samples_[count_++] = cycles;
        if (cycles > max_) max_ = cycles;
        overruns_ = overruns_total;
    }
    struct Report {
        uint32_t median = 0, max = 0, overruns = 0;
    };
    // The figures since the last take(), and a fresh start.
    Report take();

private:
    uint32_t samples_[kCapacity] = {};
    int count_ = 0;
    uint32_t max_ = 0, overruns_ = 0;
};

}  // namespace hq

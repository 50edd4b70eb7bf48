#include "loop_load.hpp"

#include <algorithm>

namespace hq {

LoopLoad::Report LoopLoad::take() {
    Report r;
    r.overruns = overruns_;
    r.max = max_;
    if (count_ > 0) {
        uint32_t* mid = samples_ + count_ / 2;
        std::nth_element(samples_, mid, samples_ + count_);
        r.median = *mid;
    }
    count_ = 0;
    max_ = 0;
    return r;
}

}  // namespace hq

// The spare-time service (spare_time.hpp).
#include "spare_time.hpp"

namespace hq {

bool SpareTime::add(SpareTask& task) {
    if (n_tasks_ == kMaxTasks) return false;
    tasks_[n_tasks_++] = &task;
    return true;
}

void SpareTime::run() {
    if (running_) return;
    running_ = true;
    for (int i = 0; i < n_tasks_; ++i) tasks_[i]->run_spare(files_);
    files_.service();
    running_ = false;
}

}  // namespace hq

// The spare-time service: the card's one owner (docs/sd-card.md, "the spare-time rule").
//
// Everything that touches the card runs from run(), in the loop's spare time: on the Teensy
// between a step's end and the next tick (LoopTimer::wait's idle work), on the host build after
// a step's reply and before the next sensor frame. Its tasks are the card's users: the logger
// draining its RAM ring into the LogSink, the log protocol answering its queued requests; after
// them the file layer's own service (the periodic sync). A task runs to its end; while it waits
// for the card the wait hook may run the loop's step (never this service: a nested run()
// returns at once, so FatFs is never entered twice).
#pragma once

#include <cstdint>

#include "log_files.hpp"

namespace hq {

// A user of the card: run_spare() does what is due, touching the card through LogFiles only.
class SpareTask {
public:
    virtual void run_spare(LogFiles& files) = 0;

protected:
    ~SpareTask() = default;
};

class SpareTime {
public:
    static constexpr int kMaxTasks = 4;

    explicit SpareTime(LogFiles& files) : files_(files) {}

    // Mounts the card (start-up only: the card's start may take milliseconds).
    CardState start() { return files_.mount(); }
    // Adds a task, run in the order added; false when kMaxTasks are there.
    bool add(SpareTask& task);
    // Runs every task once, then the files' service. Returns at once when called from inside
    // itself (through the wait hook).
    void run();
    bool running() const { return running_; }
    LogFiles& files() { return files_; }

private:
    LogFiles& files_;
    SpareTask* tasks_[kMaxTasks] = {};
    int n_tasks_ = 0;
    bool running_ = false;
};

}  // namespace hq

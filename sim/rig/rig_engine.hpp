// The lockstep loop of a simulated rig, frame after frame, in its own thread: the plant's
// sensor sample encoded as FIFO bytes, the sensor frame out, the firmware's reply in, the
// plant stepped with the reply's motors. Python (host/acquire/session.py, SilSession) starts a batch of frames with
// their RC inputs and random inputs, reads the telemetry link meanwhile, then waits for it.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

#include "plant/rig_plant.hpp"
#include "rig/sim_link.hpp"

namespace hqsim {

struct BatchResult {
    LinkStatus status = LinkStatus::Ok;
    uint32_t frames_done = 0;     // frames whose reply came back (and stepped the plant)
    uint32_t failed_frame = 0;    // the frame that failed, if status != Ok
    Reply last;                   // the last good reply (or, for WrongFrame and RotorCount,
                                  // the bad one)
};

class RigEngine {
public:
    RigEngine(SimLinkPort& port, RigPlant& plant) : port_(port), plant_(plant) {}
    ~RigEngine();

    // Frames first .. first + n - 1 at time frame * dt_us. rc: n x kRcChannels (us); noise and gust:
    // n x 6 or empty; imu_faults: n HQ_IMU_FAULT values or empty (no faults). kind: the FIFO
    // data the firmware asked for (its last reply).
    void start(uint32_t first, uint32_t n, uint32_t dt_us, uint8_t kind,
               std::vector<uint16_t> rc, std::vector<double> noise, std::vector<double> gust,
               std::vector<uint8_t> imu_faults);
    bool running() const { return running_.load(); }
    bool finished() const { return !running_.load() || done_.load(); }
    // Sleeps until the batch is finished or timeout_s passes; true if finished.
    bool wait_finished(double timeout_s);
    void cancel() { cancel_.store(true); }
    BatchResult wait();           // joins the batch's thread

private:
    void run();

    SimLinkPort& port_;
    RigPlant& plant_;
    std::thread thread_;
    std::mutex mutex_;
    std::condition_variable finished_cv_;
    std::atomic<bool> running_{false}, done_{false}, cancel_{false};
    uint32_t first_ = 0, n_ = 0, dt_us_ = 0;
    uint8_t kind_ = 0;
    std::vector<uint16_t> rc_;
    std::vector<double> noise_, gust_;
    std::vector<uint8_t> imu_faults_;
    BatchResult result_;
};

}  // namespace hqsim

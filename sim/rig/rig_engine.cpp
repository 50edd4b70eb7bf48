#include "rig/rig_engine.hpp"

#include <chrono>
#include <stdexcept>
#include <string>

#include "sensor/fifo_packets.hpp"

namespace hqsim {

RigEngine::~RigEngine() {
    cancel_.store(true);
    if (thread_.joinable()) thread_.join();
}

void RigEngine::start(uint32_t first, uint32_t n, uint32_t dt_us, uint8_t kind,
                      std::vector<uint16_t> rc, std::vector<double> noise,
                      std::vector<double> gust, std::vector<uint8_t> imu_faults) {
    if (running_.load()) throw std::logic_error("a batch is already running");
    if (rc.size() != size_t{n} * kRcChannels || (!noise.empty() && noise.size() != size_t{n} * 6) ||
        (!gust.empty() && gust.size() != size_t{n} * 6) ||
        (!imu_faults.empty() && imu_faults.size() != n)) {
        throw std::invalid_argument("rc must be n x " + std::to_string(kRcChannels) +
                                    ", noise and gust n x 6 or empty, imu_faults n or empty");
    }
    first_ = first;
    n_ = n;
    dt_us_ = dt_us;
    kind_ = kind;
    rc_ = std::move(rc);
    noise_ = std::move(noise);
    gust_ = std::move(gust);
    imu_faults_ = std::move(imu_faults);
    result_ = BatchResult{};
    cancel_.store(false);
    done_.store(false);
    running_.store(true);
    thread_ = std::thread([this] { run(); });
}

void RigEngine::run() {
    uint8_t fifo[kDmpPacketSize];
    for (uint32_t i = 0; i < n_; ++i) {
        const uint32_t frame = first_ + i;
        if (cancel_.load()) {
            result_.status = LinkStatus::Cancelled;
            result_.failed_frame = frame;
            break;
        }
        const SensorSample s = plant_.sensor(noise_.empty() ? nullptr : &noise_[6 * i]);
        const size_t len = encode_fifo(static_cast<FifoKind>(kind_), s, fifo);
        Reply reply;
        const bool last = i + 1 == n_;            // the caller reads telemetry after it
        const LinkStatus st = port_.exchange(uint64_t{frame} * dt_us_, frame, kind_, fifo, len,
                                             &rc_[kRcChannels * i], last,
                                             imu_faults_.empty() ? uint8_t{HQ_IMU_FAULT_NONE}
                                                                 : imu_faults_[i],
                                             &reply);
        if (st != LinkStatus::Ok) {
            result_.status = st;
            result_.failed_frame = frame;
            if (st == LinkStatus::WrongFrame) result_.last = reply;
            break;
        }
        // Disarmed, every motor is stopped whatever the count: a session sets a vehicle's
        // geometry (its rotor count among it) on the board before the pilot arms.
        if (reply.armed && reply.motor_count != plant_.rotors()) {
            result_.status = LinkStatus::RotorCount;
            result_.failed_frame = frame;
            result_.last = reply;
            break;
        }
        plant_.step(reply.motor.data(), gust_.empty() ? nullptr : &gust_[6 * i]);
        kind_ = reply.sensor_kind;
        result_.last = reply;
        result_.frames_done = i + 1;
    }
    {
        std::lock_guard<std::mutex> lock(mutex_);
        done_.store(true);
    }
    finished_cv_.notify_all();
}

bool RigEngine::wait_finished(double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return finished_cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                                 [this] { return finished(); });
}

BatchResult RigEngine::wait() {
    if (thread_.joinable()) thread_.join();
    running_.store(false);
    return result_;
}

}  // namespace hqsim

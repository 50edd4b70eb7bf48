// The card's two users as spare-time tasks (spare_time.hpp): the on-board log, whose RAM ring
// the FlightController's logger drains into the log file, and the MAVLink log protocol, which
// answers its queued requests from the logs on the card. Both targets run them in this order:
// the logger first, so a log just ended (disarmed) is closed before the protocol lists it.
#pragma once

#include "../flight_controller.hpp"
#include "../link/log_transfer.hpp"
#include "spare_time.hpp"

namespace hq {

class LoggerTask final : public SpareTask {
public:
    explicit LoggerTask(FlightController& fc) : fc_(fc) {}
    void run_spare(LogFiles& files) override { fc_.log_service(files); }

private:
    FlightController& fc_;
};

class LogProtocolTask final : public SpareTask {
public:
    explicit LogProtocolTask(LogTransfer& transfer) : transfer_(transfer) {}
    void run_spare(LogFiles& files) override { transfer_.service(files); }

private:
    LogTransfer& transfer_;
};

}  // namespace hq

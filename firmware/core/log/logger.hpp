// Logger: what the firmware logs in ArduPilot's DataFlash format (dataflash.hpp), one log
// per arming, and how it reaches the card. Two sides:
//
// - The step side (loop(), param_changed(); called inside the FlightController's step, never
//   touching the card): records go into a fixed RAM ring (kRingBytes), whole or not at all.
//   While armed, every step queues the system identification sample: SIDD (ArduPilot's
//   SystemID sample) and HQSD with HQMT (every field of HQ_SYSID_SAMPLE, from the same
//   LoopStatus the telemetry sends), stamped with the step's time; and as they happen: MSG
//   for every STATUSTEXT (the loop's notices from here, once; a link's own through text()
//   right after the step, see GcsLinkConfig::log), PARM for a parameter
//   changed, MODE for a mode change, EV at arming and disarming (ArduPilot's event ids
//   ARMED 10, DISARMED 11), SIDS when an excitation starts. A record that does not fit is
//   dropped and counted; the first record that fits after drops is preceded by HQGP (how
//   many were dropped, since when).
// - The service side (service(); the loop's spare time, the card's one owner): at an
//   arming it opens a log in the sink and writes the log's header straight to it (FMT for
//   every message, UNIT, MULT, FMTU, MSG with the firmware's version, PARM for every
//   parameter), then drains the ring; after the disarm, once the ring is drained up to
//   the disarm's record, it ends the log. An arming before the previous log has ended
//   continues that log.
//
// Why 2 KiB: the image keeps its static RAM within 24 KiB, and with the USB stack, both
// links, the card's driver and FatFs (its sector window and one file) that leaves the ring
// 2 KiB: about 15 loops of samples (136 B a loop), 75 ms at 200 Hz, beyond which a busy card
// costs dropped records (counted, and a gap record), never a late loop.
// The header (about 4 KiB) is never queued: the service writes it from the tables.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../excitation.hpp"
#include "../loop_exchange.hpp"
#include "../params.hpp"
#include "dataflash.hpp"
#include "log_ring.hpp"
#include "log_sink.hpp"

namespace hq {

// ArduPilot's LogEvent ids for arming and disarming (EV.Id).
constexpr uint8_t kLogEventArmed = 10, kLogEventDisarmed = 11;

struct LogCounters {
    uint32_t records = 0;        // records queued in the ring
    uint32_t dropped = 0;        // records dropped: the ring was full
    uint32_t bytes_written = 0;  // bytes the sink took (header and ring)
    uint32_t logs = 0;           // logs begun
    CardState card = CardState::NoCard;   // the sink's state when it was last served
};

class Logger {
public:
    static constexpr uint32_t kRingBytes = 2048;

    // Step side. After the step's work: the arming state, notices, mode, experiment and
    // sample of `st`; `exc` is the Supervisor's excitation (SIDS, SIDD's time and frequency).
    void loop(const LoopStatus& st, const Excitation& exc, float loop_rate_hz);
    // A parameter the step changed (PARM), while a log is being written.
    void param_changed(int index, float value, float default_value, uint64_t now_us);
    // A STATUSTEXT a link said of its own in the loop at now_us (MSG; at most len
    // characters of text), while a log is being written.
    void text(const char* words, size_t len, uint64_t now_us);

    // Service side: opens, fills and ends logs in `sink`; `params` gives the header's PARM.
    void service(LogSink& sink, const Params& params);

    // The card's state at start-up, before the first service() (which then keeps it).
    void set_card(CardState s) { counters_.card = s; }
    const LogCounters& counters() const { return counters_; }
    bool logging() const { return armed_; }
    uint32_t queued_bytes() const { return ring_.used(); }

private:
    bool push(const uint8_t* data, size_t n, uint32_t records, uint64_t now_us);
    void on_arming(const LoopStatus& st);
    void on_disarm(const LoopStatus& st);
    void log_notices(const LoopStatus& st);
    void log_text(const char* words, size_t len, uint64_t now_us);
    void log_mode(const LoopStatus& st);
    void log_experiment(const LoopStatus& st, const Excitation& exc, float loop_rate_hz);
    void log_sample(const LoopStatus& st, const Excitation& exc);
    // service(): the header's i-th record into buf (0: past the last).
    size_t header_record(uint32_t i, const Params& params, uint8_t* buf, size_t capacity) const;
    void write_header(LogSink& sink, const Params& params);
    void drain(LogSink& sink);
    bool take(LogSink& sink, const uint8_t* data, uint32_t n);

    LogRing<kRingBytes> ring_;
    LogCounters counters_{};
    // Step side.
    bool armed_ = false;
    uint32_t arms_ = 0;                 // logs asked for (armings that start a log)
    bool end_wanted_ = false;           // disarmed: end the log at end_mark_
    uint32_t end_mark_ = 0;
    uint64_t start_us_ = 0;             // the arming's time (the header's stamp)
    FlightMode mode_ = FlightMode::Angle;
    bool exciting_ = false;
    bool ended_ = false;             // the last loop ended an excitation
    uint64_t exc_start_us_ = 0;
    uint32_t gap_dropped_ = 0;          // dropped since the last HQGP
    uint64_t gap_since_us_ = 0;
    // Service side.
    bool open_ = false;                 // a log is open (or being discarded: !sink_ok_)
    bool sink_ok_ = false;
    uint32_t served_ = 0;               // the arming whose log is open or was last ended
};

}  // namespace hq

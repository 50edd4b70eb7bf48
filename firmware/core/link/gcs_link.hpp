// GcsLink: the firmware's MAVLink side, the ground station's end of the telemetry link
// (docs/link-contract.md). Before each loop step it reads the link and turns what a ground
// station asks of the loop into requests (LoopInbox, loop_exchange.hpp); after the step it
// answers every message in the order it came, from the loop's answers, and sends the
// telemetry from the loop's published state (LoopStatus). It never touches the loop itself.
//
// gcs_link.cpp: messages in, command and excitation answers, sending; param_protocol.cpp: the
// parameter protocol; telemetry.cpp: the streams; log_transfer.cpp: the log protocol
// (LogTransfer, served in spare time when the target gives the link one: serve_logs());
// program_link.cpp: the on-board program's messages (HQ_PROGRAM, HQ_PROGRAM_STATUS).
//
// Telemetry: every loop ATTITUDE and HQ_SYSID_SAMPLE (always the loop's last message);
// HEARTBEAT, HQ_FW_STATUS and SYS_STATUS once a second; SERVO_OUTPUT_RAW, SCALED_IMU,
// HIGHRES_IMU and RC_CHANNELS at 10, 10, 10 and 5 Hz; each but HEARTBEAT and
// HQ_SYSID_SAMPLE at the interval SET_MESSAGE_INTERVAL asks for, within what the link
// carries. HQ_EXCITATION_STATUS in answer to every HQ_EXCITATION and when an excitation
// ends; STATUSTEXT for every notice of the loop (Supervisor events, the IMU, the parameter
// store) and parameter refusal; COMMAND_ACK for every COMMAND_LONG and COMMAND_INT addressed
// to it or broadcast; PARAM_VALUE for the parameter protocol, a few per loop. The boot report
// (boot_report.hpp: what start-up found, one STATUSTEXT per finding, one finding a loop) on
// the first HEARTBEAT of a ground station this link has not heard (or has forgotten), and on
// MAV_CMD_REQUEST_MESSAGE for STATUSTEXT: a report under way runs to its end, a request
// during it asks for one more whole report after it, and at most one report starts a second.
// A message that does not fit the link is dropped whole and counted, never blocking the loop
// (a PARAM_VALUE or a finding of the boot report is sent again in the next loop instead).
// At most LoopInbox::kCapacity messages are taken per loop; the rest wait in the port for
// the next.
#pragma once

#include <cstdint>

#include "../../hal/serial.hpp"
#include "../boot_report.hpp"
#include "../log/logger.hpp"
#include "../loop_exchange.hpp"
#include "../loop_load.hpp"
#include "link_util.hpp"
#include "log_transfer.hpp"

#include <hq_mavlink.hpp>

namespace hq {

struct GcsLinkConfig {
    float loop_rate_hz = 200.0f;
    uint8_t system_id = 1;
    uint8_t component_id = MAV_COMP_ID_AUTOPILOT1;
    // What the telemetry link carries, bytes per second (921600 baud, 10 bits a byte):
    // SET_MESSAGE_INTERVAL refuses rates that would need more than 80 % of it.
    uint32_t link_bytes_per_s = 92160;
    // CPU cycles per second of the target's cycle counter (SYS_STATUS load); 0: none.
    uint32_t cpu_hz = 0;
    // The board's unique id (AUTOPILOT_VERSION.uid, and uid2 whole): the chip's own on the
    // Teensy (SIM_UIDH..UIDL, 128 bits, most significant word first); the host build's
    // stand-in is targets/host/main.cpp's.
    uint64_t uid = 0;
    uint8_t uid2[18] = {};
    // Which of the board's links this is (HQ_LINK: HQ_FW_STATUS.link_id and the index of its
    // per-link figures).
    uint8_t link_id = HQ_LINK_USB;
    // The on-board log (the FlightController's): the STATUSTEXTs this link says of its own
    // (a refused parameter or interval, the boot report) go there as MSG; the loop's notices
    // are logged once by the loop itself. nullptr: not logged.
    Logger* log = nullptr;
};

class GcsLink {
public:
    // `inbox` is the loop's (LoopInbox): shared by every link of the board, cleared by whoever
    // runs the loop before the links' receive().
    GcsLink(const GcsLinkConfig& config, SerialPort& port, LoopInbox& inbox);

    // Before a step: the messages waiting on the link, as requests added to inbox().
    void receive();
    LoopInbox& inbox() { return inbox_; }
    // After the step: every answer, the loop's notices and the telemetry (in that order).
    void transmit(const LoopStatus& status);
    // After the loop's init(): what it said.
    void send_notices(const LoopStatus& status);
    // The target's measurement of the loop just run: CPU cycles of its work and the loop
    // ticks missed since boot (HQ_FW_STATUS loop_cycles_*, loop_overruns).
    void record_loop(uint32_t cycles, uint32_t overruns_total) { load_.record(cycles, overruns_total); }
    uint32_t telemetry_dropped() const { return telemetry_dropped_; }
    uint32_t bytes_sent_total() const { return bytes_total_; }
    // The board's other link, whose bytes and drops this link's HQ_FW_STATUS reports beside
    // its own (a board with two links pairs them both ways).
    void pair_with(const GcsLink& other) { peer_ = &other; }
    // The log protocol's requests go to `logs` (without one they are ignored): one per board,
    // given to each of its links; the target runs logs.service() in the loop's spare time.
    void serve_logs(LogTransfer& logs) { logs_ = &logs; }

    // A message the firmware streams or sends on request (SET_MESSAGE_INTERVAL,
    // MAV_CMD_REQUEST_MESSAGE), with its interval in microseconds (0: off).
    struct Stream {
        uint32_t msgid;
        uint32_t default_us;
        uint32_t interval_us;
        bool requested;          // once, in the next loop (MAV_CMD_REQUEST_MESSAGE)
        uint64_t next_us;        // last: before it the flag fills the gap to its alignment
    };
    static constexpr int kStreams = 9;

private:
    friend class LogTransfer;                // packs with this link's ids, sends with offer()
    // A message taken this loop: what its answer needs, and its request's slot in inbox_
    // (-1: the link answers it alone). What only one kind of message carries shares one
    // place (keep() writes it and only the reply to that msgid reads it): 40 bytes, not 64,
    // so each link's LoopInbox::kCapacity (24) of them take 960 B instead of 1 536 B.
    struct Received {
        uint32_t msgid;
        uint8_t sysid, compid;
        int8_t request;
        uint8_t param_type;              // PARAM_SET
        uint16_t command;                // COMMAND_LONG, COMMAND_INT
        int16_t param_index;             // PARAM_REQUEST_READ
        union {
            float p[7];                      // COMMAND_LONG, COMMAND_INT
            char param_id[kParamNameLen];    // PARAM_REQUEST_READ, PARAM_SET
            uint8_t ftp[4];                  // FILE_TRANSFER_PROTOCOL: seq (2), session, opcode
            uint8_t program[2];              // HQ_PROGRAM: action, index
        };
    };
    static_assert(sizeof(Received) == 40, "Received: the fields and one message's own");
    // [[gnu::cold]]: what runs only when a ground station asks something, never in a loop
    // of its own, is compiled for size and kept off the per-loop paths (the unit keeps -O2
    // on the Teensy for its streams and framer; docs/teensy35.md, "Size").
    // gcs_link.cpp
    bool for_us(uint8_t target_system, uint8_t target_component) const;
    bool take(const mavlink_message_t& msg);
    [[gnu::cold]] bool keep(const mavlink_message_t& msg, Received& in) const;
    template <typename Command>
    [[gnu::cold]] bool keep_command(const Command& c, float p5, float p6, float p7,
                                    Received& in) const;
    template <typename ParamMessage>
    [[gnu::cold]] bool keep_param(const mavlink_message_t& msg,
                                  void (*decode)(const mavlink_message_t*, ParamMessage*),
                                  Received& in) const;
    bool ask(const mavlink_message_t& msg, const Received& in, bool answered, LoopRequest& r);
    [[gnu::cold]] static bool ask_command(const Received& in, LoopRequest& r);
    [[gnu::cold]] bool ask_excitation(const mavlink_message_t& msg, LoopRequest& r);
    // HQ_EXCITATION's (or HQ_PROGRAM's: Message) excitation into cfg: its numbers, signal
    // and harmonics.
    template <typename Message>
    [[gnu::cold]] static void read_excitation(const Message& ex, ExcitationConfig& cfg);
    void reply(const Received& in, const LoopAnswer* a);
    [[gnu::cold]] void reply_command(const Received& in, const LoopAnswer* a);
    [[gnu::cold]] uint8_t command_result(const Received& in, const LoopAnswer* a, Reason& why);
    [[gnu::cold]] void refuse_file_transfer(const Received& in);
    void send_excitation_status(Reason reason, const ExcitationReport& ex);
    bool send_statustext(uint8_t severity, const char* text);
    bool say(uint8_t severity, const char* text);       // sent and logged (GcsLinkConfig::log)
    void send_notices_to(const LoopStatus& status, int end);
    bool send_notice(const Notice& n, const char* prefix = "");
    void heard(StationId who);
    void send_boot_report(const BootReport& boot);
    bool send(const mavlink_message_t& msg);
    bool offer(const mavlink_message_t& msg);
    // param_protocol.cpp
    [[gnu::cold]] bool ask_param_set(const mavlink_message_t& msg, LoopRequest& r) const;
    [[gnu::cold]] void reply_param_read(const Received& in);
    [[gnu::cold]] void reply_param_set(const Received& in, const LoopAnswer* a);
    [[gnu::cold]] void send_unknown_param(const char* name, int index);
    [[gnu::cold]] void send_param_error(const Received& to, const char* name, int index,
                                        SetResult why);
    void send_params(const Tunables& values);
    bool send_param_value(const Tunables& values, int index);
    // program_link.cpp
    [[gnu::cold]] bool keep_program(const mavlink_message_t& msg, Received& in) const;
    [[gnu::cold]] bool ask_program(const mavlink_message_t& msg, LoopRequest& r);
    [[gnu::cold]] void reply_program(const Received& in, const LoopAnswer& a);
    [[gnu::cold]] void send_program_status(uint8_t action, bool accepted,
                                           const ProgramReport& report);
    // telemetry.cpp
    [[gnu::cold]] uint8_t interval_command(uint32_t msgid, float interval_us);
    [[gnu::cold]] uint8_t request_message(uint32_t msgid);
    Stream* stream(uint32_t msgid);
    bool stream_due(Stream& s, uint32_t loop_index, uint64_t now_us);
    uint32_t stream_bytes_per_s(uint32_t msgid, uint32_t interval_us) const;
    void send_telemetry(const LoopStatus& st);
    void send_stream(uint32_t msgid, const LoopStatus& st, uint64_t now_us);
    void send_heartbeat(const LoopStatus& st);
    void send_fw_status(const LoopStatus& st, uint64_t now_us);
    void send_sys_status(const LoopStatus& st);
    [[gnu::cold]] void send_autopilot_version();
    void send_servo_output(const LoopStatus& st, uint64_t now_us);
    void send_rc_channels(const LoopStatus& st, uint64_t now_us);
    void send_scaled_imu(const LoopStatus& st, uint64_t now_us);
    void send_highres_imu(const LoopStatus& st, uint64_t now_us);
    void send_attitude(const LoopStatus& st, uint64_t now_us);
    void send_sysid_sample(const LoopStatus& st, uint64_t now_us);

    GcsLinkConfig config_;
    SerialPort& port_;
    LoopInbox& inbox_;
    Received received_[LoopInbox::kCapacity];
    int received_count_ = 0;
    int notices_sent_ = 0;                   // of the loop's current notices
    uint8_t rx_buf_[64] = {};                // bytes read but not yet parsed (inbox full)
    size_t rx_len_ = 0, rx_pos_ = 0;
    bool have_held_ = false;                 // rx_msg_ is whole, but this loop had no room
    // Two one-byte members beside the flag above, in the gap before load_'s alignment.
    bool last_exc_accepted_ = false;
    uint8_t heard_count_ = 0;                // of heard_[] (below)
    LoopLoad load_{};
    LoopLoad::Report last_load_{};           // the last second's (HQ_FW_STATUS, SYS_STATUS)
    Stream streams_[kStreams];
    uint32_t seq_ = 0;
    uint64_t loop_time_us_ = 0;              // the loop being answered (LoopStatus::time_us)
    uint32_t telemetry_dropped_ = 0;         // bytes, since boot
    uint32_t bytes_total_ = 0;               // bytes sent, since boot
    const GcsLink* peer_ = nullptr;
    LogTransfer* logs_ = nullptr;
    const Program* program_ = nullptr;       // the loop's stored program (READ's answers)
    uint32_t bytes_sent_ = 0, bytes_dropped_ = 0;     // this second's, for SYS_STATUS
    uint16_t drop_rate_ = 0;                          // the last second's, 1/100 %
    ParamBits params_pending_;               // PARAM_VALUEs to send
    ParamBits params_as_float_;              // of those, answers to a set sent as REAL32
    // The ground stations this link has heard (a HEARTBEAT of MAV_TYPE_GCS), for the boot
    // report: kHeardStations of them, each with the count of heartbeats heard at its last; a
    // new one takes the place of the one heard longest ago.
    struct Heard {
        StationId who;
        uint32_t at;
    };
    static constexpr int kHeardStations = 8;
    Heard heard_[kHeardStations] = {};
    uint32_t heartbeats_heard_ = 0;
    // The boot report: the finding to send next (kBootFindings: no report under way), whether
    // one more whole report is asked for, and the loops left before another may start.
    uint8_t boot_next_ = kBootFindings;
    bool boot_asked_ = false;
    uint32_t boot_wait_loops_ = 0;
    mavlink_status_t tx_status_{};
    mavlink_status_t rx_status_{};
    mavlink_message_t rx_msg_{};             // the framer's: in the making, or held (above)
};

}  // namespace hq

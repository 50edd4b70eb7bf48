#include "sim_link_handler.hpp"

#include "rc_input.hpp"

namespace hq {

SimLinkHandler::SimLinkHandler(FlightController& fc, GcsLink& link, HostClock& clock, Mpu6050Emulator& chip,
                               const HostMotors& motors, uint8_t system_id,
                               uint8_t component_id)
    : fc_(fc), link_(link), clock_(clock), chip_(chip), motors_(motors), system_id_(system_id),
      component_id_(component_id) {}

bool SimLinkHandler::feed(const uint8_t* data, size_t n, SimLinkReplies& out) {
    for (size_t i = 0; i < n; ++i) {
        mavlink_message_t msg;
        mavlink_status_t st;
        if (mavlink_frame_char_buffer(&rx_msg_, &rx_status_, data[i], &msg, &st) !=
                MAVLINK_FRAMING_OK ||
            msg.msgid != MAVLINK_MSG_ID_HQ_SENSOR_FRAME) {
            continue;
        }
        if (!on_frame(msg, out)) return false;
    }
    return true;
}

void SimLinkHandler::apply_fault(uint8_t fault) {
    // The host bus has no timing: a stuck bus fails every transfer, as a missing chip does.
    chip_.set_present(fault != HQ_IMU_FAULT_NACK && fault != HQ_IMU_FAULT_STUCK_BUS);
    chip_.set_silent(fault == HQ_IMU_FAULT_SILENT);
    if (fault == HQ_IMU_FAULT_RESET) chip_.power_on_reset();
    if (fault == HQ_IMU_FAULT_OVERFLOW) chip_.force_overflow();
}

bool SimLinkHandler::on_frame(const mavlink_message_t& msg, SimLinkReplies& out) {
    mavlink_hq_sensor_frame_t f;
    mavlink_msg_hq_sensor_frame_decode(&msg, &f);
    if (have_last_ && f.frame == last_frame_) {          // repeated: the same reply again
        ++repeated_;
        return out.reply(out_, out_len_, f.sync != 0);
    }
    if (have_last_ && f.frame > last_frame_ + 1) lost_ += f.frame - last_frame_ - 1;
    have_last_ = true;
    last_frame_ = f.frame;
    ++frames_;
    clock_.set(f.time_us);
    apply_fault(f.imu_fault);
    const size_t len = f.fifo_len < sizeof(f.fifo) ? f.fifo_len : sizeof(f.fifo);
    if (len > 0) chip_.push_fifo(f.fifo, len, f.fifo_kind == HQ_SENSOR_DMP);
    link_.inbox().clear();
    link_.receive();
    fc_.step(rc_from_sim_frame(f.rc_us), link_.inbox());
    link_.transmit(fc_.status());
    mavlink_message_t reply;
    mavlink_msg_hq_actuator_frame_pack_status(system_id_, component_id_, &tx_status_, &reply,
                                              f.time_us, f.frame, motors_.values(),
                                              fc_.status().state.rotor_count, fc_.armed() ? 1 : 0,
                                              static_cast<uint8_t>(fc_.mode()), fc_.sensor_kind());
    out_len_ = mavlink_msg_to_send_buffer(out_, &reply);
    return out.reply(out_, out_len_, f.sync != 0);
}

}  // namespace hq

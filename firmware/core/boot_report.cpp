// The boot report's words (boot_report.hpp): one STATUSTEXT per finding, each at most 43
// characters (49 with the link's "boot: " in front); a finding that needs attention (a
// corrupt store, a stored value refused, the DMP's fallback, a reset by the watchdog or a
// fault) is a warning, a missing IMU critical.
#include "boot_report.hpp"

namespace hq {

namespace {

Notice reset_notice(ResetCause c) {
    switch (c) {
        case ResetCause::PowerOn: return {MAV_SEVERITY_INFO, "reset by power-on"};
        case ResetCause::Pin: return {MAV_SEVERITY_INFO, "reset by the reset pin"};
        case ResetCause::Watchdog: return {MAV_SEVERITY_WARNING, "reset by the watchdog"};
        case ResetCause::Lockup: return {MAV_SEVERITY_WARNING, "reset by a CPU lockup"};
        case ResetCause::Software: return {MAV_SEVERITY_INFO, "reset by software"};
        case ResetCause::LowVoltage: return {MAV_SEVERITY_WARNING, "reset by low voltage"};
        case ResetCause::ClockLoss: return {MAV_SEVERITY_WARNING, "reset by a clock loss"};
        case ResetCause::Debugger: return {MAV_SEVERITY_INFO, "reset by a debugger"};
        case ResetCause::Other: break;
    }
    return {MAV_SEVERITY_INFO, "reset, cause unknown"};
}

// Why the DMP set-up fell back to the raw path.
const char* dmp_failure_text(DmpStep step) {
    switch (step) {
        case DmpStep::Tables: return "IMU: DMP tables missing or bad; raw path";
        case DmpStep::Image: return "IMU: DMP image did not verify; raw path";
        case DmpStep::Config: return "IMU: DMP config did not verify; raw path";
        case DmpStep::Registers: return "IMU: DMP set-up bus error; raw path";
        case DmpStep::Updates: return "IMU: DMP updates did not verify; raw path";
        case DmpStep::None: break;
    }
    return "IMU: DMP set-up failed; raw path";
}

}  // namespace

Notice boot_finding(const BootReport& report, int i) {
    if (i == 0) return reset_notice(report.reset);
    if (i == 1) return params_notice(report.params, report.param_index, report.param_result);
    if (i == 2) return imu_notice(report.imu, report.dmp_step);
    return card_notice(report.card);
}

// Logging is no flight safety item: a card that cannot log is a warning, never more.
Notice card_notice(CardState s) {
    switch (s) {
        case CardState::Ok: return {MAV_SEVERITY_INFO, "SD: card ok; logging each arming"};
        case CardState::NoCard: return {MAV_SEVERITY_NOTICE, "SD: no card; no on-board log"};
        case CardState::WriteProtected:
            return {MAV_SEVERITY_WARNING, "SD: card write-protected; no log"};
        case CardState::Full: return {MAV_SEVERITY_WARNING, "SD: card full; no log"};
        case CardState::Failed: break;
    }
    return {MAV_SEVERITY_WARNING, "SD: card failed; no log"};
}

Notice params_notice(ParamsFinding f, int param_index, SetResult param_result) {
    switch (f) {
        case ParamsFinding::NoStorage: return {MAV_SEVERITY_INFO, "params: no storage; defaults"};
        case ParamsFinding::Loaded: return {MAV_SEVERITY_INFO, "params: loaded from the store"};
        case ParamsFinding::Empty: return {MAV_SEVERITY_INFO, "params: none stored; defaults"};
        case ParamsFinding::Corrupt: break;
        case ParamsFinding::OutOfRange:          // its words: set_result_text(result, index)
            return {MAV_SEVERITY_WARNING, nullptr, param_index, param_result};
    }
    return {MAV_SEVERITY_WARNING, "params: store corrupt; defaults loaded"};
}

Notice imu_notice(ImuFinding f, DmpStep step) {
    switch (f) {
        case ImuFinding::Dmp: return {MAV_SEVERITY_INFO, "IMU: MPU6050 found; DMP path"};
        case ImuFinding::RawByParam:
            return {MAV_SEVERITY_INFO, "IMU: MPU6050 found; raw path (IMU_PATH)"};
        case ImuFinding::RawNoImage:
            return {MAV_SEVERITY_INFO, "IMU: MPU6050 found; raw path (no DMP)"};
        case ImuFinding::RawFallback: return {MAV_SEVERITY_WARNING, dmp_failure_text(step)};
        case ImuFinding::Missing: break;
    }
    return {MAV_SEVERITY_CRITICAL, "IMU: MPU6050 not found"};
}

ImuFinding imu_finding(InitResult r, ImuPath path) {
    switch (r) {
        case InitResult::OkDmp: return ImuFinding::Dmp;
        case InitResult::OkRaw:
            return path == ImuPath::Raw ? ImuFinding::RawByParam : ImuFinding::RawNoImage;
        case InitResult::OkRawFallback: return ImuFinding::RawFallback;
        case InitResult::NoDevice:
        case InitResult::BusError: break;
    }
    return ImuFinding::Missing;
}

bool announced(ParamsFinding f) {
    return f != ParamsFinding::NoStorage && f != ParamsFinding::Loaded;
}

bool announced(ImuFinding f) { return f == ImuFinding::RawFallback || f == ImuFinding::Missing; }

}  // namespace hq

// Eight ESC outputs on FTM0 channels 0-7, standard 400 Hz PWM, rotor i on channel i.
//
//   rotor    0 (central)  1          2          3          4          5          6          7
//   channel  FTM0 CH0     CH1        CH2        CH3        CH4        CH5        CH6        CH7
//   pin      22 (PTC1)    23 (PTC2)  9 (PTC3)   10 (PTC4)  6 (PTD4)   20 (PTD5)  21 (PTD6)  5 (PTD7)
//
// (The five-rotor vehicle's rotors 1-4 are front, right, back, left.) All eight pins are
// FTM0 on ALT4 (K64 data sheet, "K64 Signal Multiplexing and Pin Assignments").
//
// FTM0 counts the bus clock / 4 = 15 MHz: 2.5 ms period = 37 500 counts, 15 counts per
// microsecond. A thrust fraction f (0..1) becomes min_us + f (max_us - min_us) for each
// ESC's own calibration, rounded to the count (1/15 us); anything not finite becomes 0. The
// channels past the rotor count the loop flies get their stop pulse, armed or not. begin()
// loads every channel with the ESC's stop pulse (its min_us) before the pins are switched to
// FTM0, so from the first edge an ESC sees nothing but "stop" until the vehicle arms. Channel
// values take effect at the next period boundary (FTM0 buffers CnV in this mode), so a pulse
// is never cut short.
#pragma once

#include <cstdint>

#include "../../hal/motors.hpp"

namespace hq::teensy {


class Ftm0Motors final : public MotorOutputs {
public:
    static constexpr uint32_t kPwmHz = 400;
    static constexpr uint32_t kCountsPerUs = 15;                 // bus 60 MHz / 4
    static constexpr uint32_t kPeriodCounts = 1000000 / kPwmHz * kCountsPerUs;

    // Endpoints outside 800..2200 us, or with max <= min, are replaced by 1000/2000.
    void begin(const EscEndpoints& cal);
    void set(const float thrust_fraction[kMaxRotors], int count) override;
    void disarm() override;
    // Implausible endpoints keep that ESC's previous ones; the stop pulses go out at once.
    void set_endpoints(const EscEndpoints& endpoints) override;

private:
    void write(int i, uint16_t us);
    EscEndpoints cal_{};
};

// Drives every ESC channel to its stop pulse if FTM0 is running; for the fault path.
void motors_emergency_stop();

}  // namespace hq::teensy

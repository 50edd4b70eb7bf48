// Parameter storage: where the firmware keeps its parameters across a reset or a restart
// (the host build: a file named on its command line; the Teensy: two sectors of its flash).
// Contract:
// - It holds one record of at most kMaxBytes, saved whole or not at all: a reset or a power
//   loss during save() leaves the previous record loadable (or none), never a mix of two.
// - load() copies the last record saved into data and says what it found: Ok (n bytes), Empty
//   (nothing was ever saved: a blank device, no file) or Corrupt (something is stored but
//   fails the backend's own check). The core checks the record's own format and checksum
//   on top (params.hpp), so a backend without a check of its own may always answer Ok.
// - save() blocks until the record is written and read back equal, and returns false when
//   it is not. On flash this takes tens of milliseconds: the firmware saves only while
//   disarmed.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hq {

enum class StoreStatus : uint8_t { Ok = 0, Empty = 1, Corrupt = 2 };

class ParamStorage {
public:
    static constexpr size_t kMaxBytes = 1024;

    virtual StoreStatus load(uint8_t* data, size_t capacity, size_t& n) = 0;
    virtual bool save(const uint8_t* data, size_t n) = 0;

protected:
    ~ParamStorage() = default;     // not deleted through the interface: no heap on the target
};

}  // namespace hq

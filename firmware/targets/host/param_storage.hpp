// Host backend of the HAL parameter storage (hal/param_storage.hpp): one file, named on
// heliquad-fw-host's command line (--params FILE). The file holds the record as the core
// encodes it, nothing else; the core's own checks find a damaged one. A save writes a
// temporary file beside it, flushes it to the disk and renames it over the old one, so a
// crash leaves either the old record or the new one.
#pragma once

#include <string>

#include "../../hal/param_storage.hpp"

namespace hq {

class FileParamStorage final : public ParamStorage {
public:
    explicit FileParamStorage(std::string path) : path_(std::move(path)) {}

    // Empty when the file does not exist; Corrupt when it cannot be read or is larger
    // than a record can be.
    StoreStatus load(uint8_t* data, size_t capacity, size_t& n) override;
    bool save(const uint8_t* data, size_t n) override;

    const std::string& path() const { return path_; }

private:
    std::string path_;
};

}  // namespace hq

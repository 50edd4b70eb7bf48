// Card-image files made by FatFs's f_mkfs (card_image.hpp).
#include "card_image.hpp"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <unistd.h>

#include "../../core/log/card_disk.hpp"
#include "block_device.hpp"
#include "ff.h"

namespace hq {
namespace {

// f_mkfs's work area: larger writes the FATs' zeros in fewer transfers.
constexpr UINT kMkfsWorkBytes = 32 * 1024;

// The card image's time: f_mkfs waits for nothing, so a clock that never moves will do.
class StillClock final : public Clock {
public:
    uint64_t micros() const override { return 0; }
    void delay_us(uint32_t) override {}
};

// An empty file of `bytes` (sparse: a hole until written).
std::string make_empty(const std::string& path, uint64_t bytes) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) return path + ": " + std::strerror(errno);
    const bool ok = ::ftruncate(fd, static_cast<off_t>(bytes)) == 0;
    const int err = errno;
    ::close(fd);
    return ok ? std::string() : path + ": " + std::strerror(err);
}

}  // namespace

std::string make_card_image(const std::string& path, uint64_t bytes) {
    if (bytes % BlockDevice::kBlockBytes != 0) return "the card's size must be a multiple of 512 bytes";
    if (bytes < kMinCardImageBytes || bytes > kMaxCardImageBytes) {
        return "the card's size must be 40 MiB to 32 GiB (FAT32)";
    }
    std::string error = make_empty(path, bytes);
    if (!error.empty()) return error;
    StillClock clock;
    FileBlockDevice card(path, clock);
    card_disk_attach(&card, nullptr);
    static BYTE work[kMkfsWorkBytes];              // not on the stack
    // FAT32 with two FATs (as SD cards come), no partition table, FatFs's cluster size.
    const MKFS_PARM opt = {FM_FAT32 | FM_SFD, 2, 0, 0, 0};
    const FRESULT res = f_mkfs("", &opt, work, sizeof work);
    card_disk_attach(nullptr, nullptr);
    if (res != FR_OK) return path + ": FatFs could not format it (f_mkfs result " + std::to_string(res) + ")";
    return std::string();
}

}  // namespace hq

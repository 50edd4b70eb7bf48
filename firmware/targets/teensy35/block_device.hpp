// The Teensy 3.5's built-in microSD socket through the MK64's SDHC controller: a BlockDevice
// (hal/block_device.hpp) of 512-byte blocks, 4-bit bus at 24 MHz, every transfer by the
// controller's ADMA2 engine (docs/teensy35.md, "The SD card").
//
// start() identifies the card at 375 kHz (CMD0, CMD8 with the 0x1AA check pattern, ACMD41
// with HCS until ready, CMD2, CMD3, CMD9, CMD7, ACMD6, CMD16) and is the one call that waits
// (bounded, the clock's delay_us between ACMD41 tries). Only SDHC/SDXC cards (block-addressed,
// a version 2 CSD) are used: a version 1 or standard-capacity card is refused (finding()
// says Unsupported, start() says Failed). The socket has no write-protect switch: the card's
// own PERM_WRITE_PROTECT/TMP_WRITE_PROTECT (CSD) make it read only.
//
// begin_read()/begin_write() write the controller's registers and return; poll() reads them
// and returns: never a wait. A write (CMD25 with auto-CMD12) stays Busy until the card
// releases DAT0. A controller error (IRQSTAT CTOE, CCE, CEBE, CIE, DTOE, DCE, DEBE, AC12E,
// DMAE) or an error bit in the card's R1 status makes poll() say Failed once: the flags are
// cleared, the command and data lines reset (SYSCTL RSTC, RSTD) and the card told to stop
// (CMD12), so the next transfer works. No interrupt is used: the spare-time service polls.
#pragma once

#include <cstdint>

#include "../../hal/block_device.hpp"
#include "../../hal/clock.hpp"

namespace hq::teensy {

class SdhcCard final : public BlockDevice {
public:
    // What start() found last (also after a failed transfer: Ready stays Ready).
    enum class Finding : uint8_t {
        NotStarted = 0,
        NoCard = 1,         // no answer to CMD8 or CMD55
        Unsupported = 2,    // a version 1 or standard-capacity (byte-addressed) card
        NotReady = 3,       // ACMD41 never said ready within its tries
        Error = 4,          // an answer was wrong (CRC, index, timeout after identification)
        Ready = 5,
    };
    // ADMA2 descriptors per transfer and blocks each: 4 x 64 = 256 blocks at a time (a longer
    // transfer continues in poll()).
    static constexpr uint32_t kDescriptors = 4;
    static constexpr uint32_t kBlocksPerDescriptor = 64;

    explicit SdhcCard(Clock& clock) : clock_(clock) {}

    BlockStatus start() override;
    uint32_t block_count() const override { return blocks_; }
    bool write_protected() const override { return write_protected_; }
    BlockStatus begin_read(uint32_t lba, uint8_t* data, uint32_t n) override;
    BlockStatus begin_write(uint32_t lba, const uint8_t* data, uint32_t n) override;
    BlockStatus poll() override;
    Finding finding() const { return finding_; }
    // The SD clock now (375 kHz while identifying, 24 MHz after), for the report.
    uint32_t bus_hz() const { return bus_hz_; }

private:
    struct Descriptor {     // ADMA2: attributes and length, then the buffer's address
        uint32_t attr_length;
        uint32_t address;
    };
    BlockStatus identify();
    bool command(uint32_t index, uint32_t arg, uint32_t flags, uint32_t timeout_us);
    bool app_command(uint32_t index, uint32_t arg, uint32_t flags);
    bool read_csd();
    void set_clock(uint32_t sdclkfs, uint32_t dvs, uint32_t hz);
    BlockStatus begin(uint32_t lba, uint8_t* data, uint32_t n, bool write);
    void start_chunk();
    BlockStatus fail();
    bool lines_free() const;

    Clock& clock_;
    Finding finding_ = Finding::NotStarted;
    uint32_t blocks_ = 0;
    uint32_t rca_ = 0;
    uint32_t bus_hz_ = 0;
    bool write_protected_ = false;
    // The transfer under way: what is left after the chunk the controller has now.
    bool active_ = false;
    bool need_stop_ = false;  // a failure left the card in a data state: CMD12 first
    bool write_ = false;
    bool bounce_ = false;   // an unaligned buffer: one block at a time through bounce_buf_
    uint32_t lba_ = 0;
    uint8_t* data_ = nullptr;
    uint32_t left_ = 0;
    uint32_t chunk_ = 0;
    alignas(4) Descriptor table_[kDescriptors] = {};
    alignas(4) uint8_t bounce_buf_[kBlockBytes] = {};
};

}  // namespace hq::teensy

// SdhcCard: the microSD socket on the SDHC controller (block_device.hpp says what and why).
#include "block_device.hpp"

#include <cstring>

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

namespace {

namespace sd = mk64::SDHC;
using X = sd::XFERTYP;

// Response kinds (XFERTYP RSPTYP: 0 none, 1 136 bits, 2 48 bits, 3 48 bits with busy) and the
// checks the controller makes (the SD physical layer specification's R1/R1b/R2/R3/R6/R7).
constexpr uint32_t kNoResponse = 0;
constexpr uint32_t kR1 = X::RSPTYP(2) | X::CCCEN | X::CICEN;   // R6 and R7 alike
constexpr uint32_t kR1b = X::RSPTYP(3) | X::CCCEN | X::CICEN;
constexpr uint32_t kR2 = X::RSPTYP(1) | X::CCCEN;               // no index in R2
constexpr uint32_t kR3 = X::RSPTYP(2);                          // OCR: no CRC, no index

constexpr uint32_t kErrors = sd::IRQSTAT::CTOE | sd::IRQSTAT::CCE | sd::IRQSTAT::CEBE |
                             sd::IRQSTAT::CIE | sd::IRQSTAT::DTOE | sd::IRQSTAT::DCE |
                             sd::IRQSTAT::DEBE | sd::IRQSTAT::AC12E | sd::IRQSTAT::DMAE;
constexpr uint32_t kDat0 = sd::PRSSTAT::DLSL(1);      // DAT0 high: the card is not busy

// Card status bits (R1) that fail a transfer: OUT_OF_RANGE, ADDRESS_ERROR, BLOCK_LEN_ERROR,
// WP_VIOLATION, CARD_ECC_FAILED, CC_ERROR, ERROR. ILLEGAL_COMMAND is left out: it reports
// the command before (the stop that follows a failure may be one).
constexpr uint32_t kR1Errors = 0xE4380000u;

constexpr uint32_t kCheckPattern = 0x1AA;         // CMD8: 2.7-3.6 V, pattern 0xAA
constexpr uint32_t kOcrHcs = 1u << 30;            // ACMD41: host supports high capacity
constexpr uint32_t kOcrWindow = 0x00300000u;      // 3.2-3.4 V (the Teensy's 3.3 V)
constexpr uint32_t kOcrReady = 1u << 31;
constexpr uint32_t kOcrCcs = 1u << 30;            // card capacity status: block-addressed
constexpr uint32_t kAcmd41Tries = 1000;           // 1 ms apart: the specification's 1 s
constexpr uint32_t kAcmd41PauseUs = 1000;
constexpr uint32_t kCommandTimeoutUs = 10000;
constexpr uint32_t kBusyTimeoutUs = 250000;       // CMD7's busy, controller resets

// The SDHC's clock is the system clock (SIM_SOPT2.SDHCSRC = 0, its reset value): 120 MHz.
// SD clock = 120 MHz / (SDCLKFS prescaler x (DVS + 1)).
constexpr uint32_t kIdentFs = 0x10, kIdentDvs = 9, kIdentHz = 375000;    // /32 /10
constexpr uint32_t kFastFs = 0x00, kFastDvs = 4, kFastHz = 24000000;     // /1 /5
static_assert(kCoreHz / (2 * kIdentFs * (kIdentDvs + 1)) == kIdentHz, "ident clock");
static_assert(kCoreHz / (kFastDvs + 1) == kFastHz && kFastHz <= 25000000, "25 MHz at most");
constexpr uint32_t kDataTimeout = 0xE;            // DTOCV: SDCLK x 2^27 (5.6 s at 24 MHz)

// ADMA2 descriptor attributes: valid, end, and the "transfer data" action.
constexpr uint32_t kAdmaValid = 1u << 0;
constexpr uint32_t kAdmaEnd = 1u << 1;
constexpr uint32_t kAdmaTran = 2u << 4;

// PTE0..PTE5 on ALT4: DAT1, DAT0, CLK, CMD, DAT3, DAT2 (the Teensy 3.5 schematic).
constexpr uint32_t kClkPin = 2;
constexpr uint32_t kPinMux = 4;

// Spins until (read() & mask) == want or timeout_us passes; true if it did.
template <typename Read>
bool wait_for(Read read, uint32_t mask, uint32_t want, uint32_t timeout_us) {
    const uint32_t t0 = cycles32();
    const uint32_t limit = timeout_us * (kCoreHz / 1000000u);
    while ((read() & mask) != want) {
        if (cycles32() - t0 > limit) return false;
    }
    return true;
}

void setup_pins() {
    namespace pe = mk64::PORTE;
    mk64::SIM::SCGC5::set(mk64::SIM::SCGC5::PORTE);
    const uint32_t data = pe::PCR0::MUX(kPinMux) | pe::PCR0::DSE | pe::PCR0::PE | pe::PCR0::PS;
    for (int pin = 0; pin < 6; ++pin) {
        const uint32_t pcr = pin == static_cast<int>(kClkPin) ? (pe::PCR0::MUX(kPinMux) | pe::PCR0::DSE) : data;
        reg_at<pe::PCR0>(pin, 1) = pcr;
    }
}

}  // namespace

bool SdhcCard::lines_free() const {
    const uint32_t busy = sd::PRSSTAT::CIHB | sd::PRSSTAT::CDIHB;
    return (sd::PRSSTAT::read() & (busy | kDat0)) == kDat0 &&
           (sd::SYSCTL::read() & (sd::SYSCTL::RSTC | sd::SYSCTL::RSTD)) == 0;
}

bool SdhcCard::command(uint32_t index, uint32_t arg, uint32_t flags, uint32_t timeout_us) {
    if (!wait_for(sd::PRSSTAT::read, sd::PRSSTAT::CIHB | sd::PRSSTAT::CDIHB, 0, timeout_us)) {
        return false;
    }
    sd::IRQSTAT::write(0xFFFFFFFFu);
    sd::CMDARG::write(arg);
    sd::XFERTYP::write(X::CMDINX(index) | flags);
    const uint32_t done = sd::IRQSTAT::CC | kErrors;
    if (!wait_for(sd::IRQSTAT::read, done, sd::IRQSTAT::CC, timeout_us)) return false;
    if ((flags & X::RSPTYP_MASK) == X::RSPTYP(3)) {     // R1b: wait for DAT0 to come back
        return wait_for(sd::PRSSTAT::read, kDat0, kDat0, kBusyTimeoutUs);
    }
    return true;
}

bool SdhcCard::app_command(uint32_t index, uint32_t arg, uint32_t flags) {
    return command(55, rca_, kR1, kCommandTimeoutUs) &&
           command(index, arg, flags, kCommandTimeoutUs);
}

void SdhcCard::set_clock(uint32_t sdclkfs, uint32_t dvs, uint32_t hz) {
    sd::SYSCTL::clear(sd::SYSCTL::SDCLKEN);
    const uint32_t keep = sd::SYSCTL::read() &
                          ~(sd::SYSCTL::SDCLKFS_MASK | sd::SYSCTL::DVS_MASK | sd::SYSCTL::DTOCV_MASK);
    sd::SYSCTL::write(keep | sd::SYSCTL::SDCLKFS(sdclkfs) | sd::SYSCTL::DVS(dvs) |
                      sd::SYSCTL::DTOCV(kDataTimeout) | sd::SYSCTL::IPGEN |
                      sd::SYSCTL::HCKEN | sd::SYSCTL::PEREN);
    wait_for(sd::PRSSTAT::read, sd::PRSSTAT::SDSTB, sd::PRSSTAT::SDSTB, kCommandTimeoutUs);
    sd::SYSCTL::set(sd::SYSCTL::SDCLKEN);
    bus_hz_ = hz;
}

BlockStatus SdhcCard::start() {
    active_ = false;
    need_stop_ = false;
    blocks_ = 0;
    rca_ = 0;
    write_protected_ = false;
    mk64::SIM::SCGC3::set(mk64::SIM::SCGC3::SDHC);
    setup_pins();
    // The SDHC is crossbar master 5: the MPU's region 0 lets it reach SRAM for ADMA2.
    namespace mpu = mk64::MPU;
    mpu::RGDAAC0::write(mpu::RGDAAC0::read() | mpu::RGDAAC0::M5RE | mpu::RGDAAC0::M5WE);
    sd::SYSCTL::set(sd::SYSCTL::RSTA);
    if (!wait_for(sd::SYSCTL::read, sd::SYSCTL::RSTA, 0, kBusyTimeoutUs)) {
        finding_ = Finding::Error;
        return BlockStatus::Failed;
    }
    sd::PROCTL::write(sd::PROCTL::EMODE(2) | sd::PROCTL::DMAS(2));  // little endian, ADMA2
    sd::IRQSIGEN::write(0);                                          // polled, no interrupt
    set_clock(kIdentFs, kIdentDvs, kIdentHz);
    sd::SYSCTL::set(sd::SYSCTL::INITA);                              // 80 clocks first
    wait_for(sd::SYSCTL::read, sd::SYSCTL::INITA, 0, kCommandTimeoutUs);
    return identify();
}

BlockStatus SdhcCard::identify() {
    finding_ = Finding::NoCard;
    command(0, 0, kNoResponse, kCommandTimeoutUs);
    if (!command(8, kCheckPattern, kR1, kCommandTimeoutUs)) {
        // No answer to CMD8: no card, or a version 1 card (which answers CMD55).
        if (!command(55, 0, kR1, kCommandTimeoutUs)) return BlockStatus::NoCard;
        finding_ = Finding::Unsupported;
        return BlockStatus::Failed;
    }
    finding_ = Finding::Error;
    if ((sd::CMDRSP0::read() & 0xFFFu) != kCheckPattern) return BlockStatus::Failed;
    uint32_t ocr = 0;
    for (uint32_t i = 0; i < kAcmd41Tries && (ocr & kOcrReady) == 0; ++i) {
        if (i != 0) clock_.delay_us(kAcmd41PauseUs);
        if (!app_command(41, kOcrHcs | kOcrWindow, kR3)) return BlockStatus::Failed;
        ocr = sd::CMDRSP0::read();
    }
    if ((ocr & kOcrReady) == 0) {
        finding_ = Finding::NotReady;
        return BlockStatus::Failed;
    }
    if ((ocr & kOcrCcs) == 0) {
        finding_ = Finding::Unsupported;
        return BlockStatus::Failed;
    }
    if (!command(2, 0, kR2, kCommandTimeoutUs) || !command(3, 0, kR1, kCommandTimeoutUs)) {
        return BlockStatus::Failed;
    }
    rca_ = sd::CMDRSP0::read() & 0xFFFF0000u;
    if (!read_csd()) return BlockStatus::Failed;
    if (!command(7, rca_, kR1b, kCommandTimeoutUs) || !app_command(6, 2, kR1)) {
        return BlockStatus::Failed;
    }
    sd::PROCTL::write((sd::PROCTL::read() & ~sd::PROCTL::DTW_MASK) | sd::PROCTL::DTW(1));
    if (!command(16, kBlockBytes, kR1, kCommandTimeoutUs)) return BlockStatus::Failed;
    set_clock(kFastFs, kFastDvs, kFastHz);
    finding_ = Finding::Ready;
    return BlockStatus::Ok;
}

// CSD (CMD9, R2): the controller keeps bits 127:8 of the response, shifted right by 8, in
// CMDRSP3..0; so CSD bit k is bit k - 8 of that 120-bit value.
bool SdhcCard::read_csd() {
    if (!command(9, rca_, kR2, kCommandTimeoutUs)) return false;
    const uint32_t structure = (sd::CMDRSP3::read() >> 22) & 3u;   // CSD 127:126
    if (structure != 1) {                                           // not a version 2 CSD
        finding_ = Finding::Unsupported;
        return false;
    }
    const uint32_t c_size = (sd::CMDRSP1::read() >> 8) & 0x3FFFFFu; // CSD 69:48
    blocks_ = (c_size + 1) * 1024u;
    write_protected_ = (sd::CMDRSP0::read() & 0x30u) != 0;          // CSD 13 PERM, 12 TMP
    return true;
}

BlockStatus SdhcCard::begin_read(uint32_t lba, uint8_t* data, uint32_t n) {
    return begin(lba, data, n, false);
}

BlockStatus SdhcCard::begin_write(uint32_t lba, const uint8_t* data, uint32_t n) {
    // The buffer is only read on a write (the DMA engine's reads, or the bounce copy).
    return begin(lba, const_cast<uint8_t*>(data), n, true);
}

BlockStatus SdhcCard::begin(uint32_t lba, uint8_t* data, uint32_t n, bool write) {
    if (finding_ != Finding::Ready) return BlockStatus::NoCard;
    if (active_ || !lines_free()) return BlockStatus::Busy;
    if (need_stop_) {                   // after a failure: the card leaves its data state
        need_stop_ = false;
        sd::IRQSTAT::write(0xFFFFFFFFu);
        sd::CMDARG::write(0);
        sd::XFERTYP::write(X::CMDINX(12) | kR1b);
        return BlockStatus::Busy;
    }
    if (n == 0 || lba >= blocks_ || n > blocks_ - lba) return BlockStatus::OutOfRange;
    if (write && write_protected_) return BlockStatus::WriteProtected;
    write_ = write;
    lba_ = lba;
    data_ = data;
    left_ = n;
    bounce_ = (reinterpret_cast<uintptr_t>(data) & 3u) != 0;   // ADMA2 needs word alignment
    active_ = true;
    start_chunk();
    return BlockStatus::Ok;
}

void SdhcCard::start_chunk() {
    const uint32_t most = kDescriptors * kBlocksPerDescriptor;
    chunk_ = bounce_ ? 1 : (left_ < most ? left_ : most);
    uint8_t* buf = bounce_ ? bounce_buf_ : data_;
    if (bounce_ && write_) std::memcpy(bounce_buf_, data_, kBlockBytes);
    uint32_t blocks = chunk_;
    for (uint32_t i = 0; i < kDescriptors && blocks != 0; ++i) {
        const uint32_t take = blocks < kBlocksPerDescriptor ? blocks : kBlocksPerDescriptor;
        blocks -= take;
        table_[i].attr_length = (take * kBlockBytes) << 16 | kAdmaValid | kAdmaTran |
                                (blocks == 0 ? kAdmaEnd : 0u);
        table_[i].address = static_cast<uint32_t>(reinterpret_cast<uintptr_t>(buf));
        buf += take * kBlockBytes;
    }
    dsb();                              // the table in SRAM before the engine reads it
    sd::ADSADDR::write(static_cast<uint32_t>(reinterpret_cast<uintptr_t>(table_)));
    sd::BLKATTR::write(sd::BLKATTR::BLKSIZE(kBlockBytes) | sd::BLKATTR::BLKCNT(chunk_));
    sd::IRQSTAT::write(0xFFFFFFFFu);
    sd::CMDARG::write(lba_);
    const uint32_t data = X::DPSEL | X::DMAEN | kR1;
    const uint32_t multi = X::MSBSEL | X::BCEN | X::AC12EN;
    if (write_) {
        sd::XFERTYP::write(X::CMDINX(25) | data | multi);
    } else {
        sd::XFERTYP::write(X::CMDINX(chunk_ == 1 ? 17 : 18) | data | X::DTDSEL |
                           (chunk_ == 1 ? 0u : multi));
    }
}

BlockStatus SdhcCard::poll() {
    if (!active_) return BlockStatus::Ok;
    const uint32_t irq = sd::IRQSTAT::read();
    if ((irq & kErrors) != 0) return fail();
    if ((irq & sd::IRQSTAT::CC) != 0 && (sd::CMDRSP0::read() & kR1Errors) != 0) return fail();
    if ((irq & sd::IRQSTAT::TC) == 0) return BlockStatus::Busy;
    if ((sd::PRSSTAT::read() & kDat0) == 0) return BlockStatus::Busy;   // still programming
    if (bounce_ && !write_) std::memcpy(data_, bounce_buf_, kBlockBytes);
    lba_ += chunk_;
    data_ += chunk_ * kBlockBytes;
    left_ -= chunk_;
    if (left_ == 0) {
        active_ = false;
        return BlockStatus::Ok;
    }
    start_chunk();
    return BlockStatus::Busy;
}

// An error: flags cleared, the command and data circuits reset; the stop (CMD12) goes out
// with the next begin_*() once the resets are done.
BlockStatus SdhcCard::fail() {
    sd::IRQSTAT::write(0xFFFFFFFFu);
    sd::SYSCTL::set(sd::SYSCTL::RSTC | sd::SYSCTL::RSTD);
    active_ = false;
    need_stop_ = true;
    return BlockStatus::Failed;
}

}  // namespace hq::teensy

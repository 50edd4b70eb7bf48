// FatFs's disk functions on a BlockDevice (card_disk.hpp).
#include "card_disk.hpp"

#include "ff.h"
#include "diskio.h"   // after ff.h: it uses ff.h's types

namespace hq {
namespace {

// The drive's binding: FatFs calls C functions with only a drive number, so the card and the
// hook it waits with are file statics (one card, one owner).
BlockDevice* g_card = nullptr;
CardWait* g_wait = nullptr;
DSTATUS g_status = STA_NOINIT;
BlockStatus g_last_error = BlockStatus::Ok;

// Waits out a Busy answer: one hook call per poll.
BlockStatus wait_done() {
    BlockStatus s = g_card->poll();
    while (s == BlockStatus::Busy) {
        if (g_wait != nullptr) g_wait->card_busy();
        s = g_card->poll();
    }
    return s;
}

DRESULT to_result(BlockStatus s) {
    if (s != BlockStatus::Ok) g_last_error = s;
    switch (s) {
        case BlockStatus::Ok: return RES_OK;
        case BlockStatus::WriteProtected: return RES_WRPRT;
        case BlockStatus::NoCard: return RES_NOTRDY;
        case BlockStatus::OutOfRange: return RES_PARERR;
        default: return RES_ERROR;
    }
}

// One transfer: begun (after the previous one ends: the device says Busy until then), then
// polled to its end.
template <typename Begin>
DRESULT transfer(Begin begin) {
    if (g_card == nullptr || (g_status & STA_NOINIT) != 0) return RES_NOTRDY;
    BlockStatus s = begin();
    while (s == BlockStatus::Busy) {
        if (g_wait != nullptr) g_wait->card_busy();
        s = begin();
    }
    if (s == BlockStatus::Ok) s = wait_done();
    return to_result(s);
}

}  // namespace

void card_disk_attach(BlockDevice* card, CardWait* wait) {
    g_card = card;
    g_wait = wait;
    g_status = STA_NOINIT;
    g_last_error = BlockStatus::Ok;
}

BlockStatus card_disk_last_error() { return g_last_error; }

}  // namespace hq

using hq::BlockStatus;

extern "C" DSTATUS disk_initialize(BYTE pdrv) {
    if (pdrv != 0 || hq::g_card == nullptr) return STA_NOINIT | STA_NODISK;
    const BlockStatus s = hq::g_card->start();
    if (s != BlockStatus::Ok) {
        hq::g_last_error = s;
        hq::g_status = static_cast<DSTATUS>(STA_NOINIT | (s == BlockStatus::NoCard ? STA_NODISK : 0));
        return hq::g_status;
    }
    hq::g_status = hq::g_card->write_protected() ? STA_PROTECT : 0;
    return hq::g_status;
}

extern "C" DSTATUS disk_status(BYTE pdrv) {
    return pdrv == 0 ? hq::g_status : static_cast<DSTATUS>(STA_NOINIT);
}

extern "C" DRESULT disk_read(BYTE pdrv, BYTE* buff, LBA_t sector, UINT count) {
    if (pdrv != 0) return RES_PARERR;
    return hq::transfer([&] { return hq::g_card->begin_read(sector, buff, count); });
}

extern "C" DRESULT disk_write(BYTE pdrv, const BYTE* buff, LBA_t sector, UINT count) {
    if (pdrv != 0) return RES_PARERR;
    return hq::transfer([&] { return hq::g_card->begin_write(sector, buff, count); });
}

extern "C" DRESULT disk_ioctl(BYTE pdrv, BYTE cmd, void* buff) {
    if (pdrv != 0 || hq::g_card == nullptr || (hq::g_status & STA_NOINIT) != 0) return RES_NOTRDY;
    switch (cmd) {
        case CTRL_SYNC:   // every write was polled to its end (the card's busy included)
            return hq::to_result(hq::wait_done());
        case GET_SECTOR_COUNT:
            *static_cast<LBA_t*>(buff) = hq::g_card->block_count();
            return RES_OK;
        case GET_BLOCK_SIZE:   // the erase block in blocks; 1: unknown (FatFs then aligns to 1)
            *static_cast<DWORD*>(buff) = 1;
            return RES_OK;
        default:
            return RES_PARERR;
    }
}

// The card as FatFs's drive 0: the diskio functions ff.c calls (disk_initialize, disk_status,
// disk_read, disk_write, disk_ioctl) on a hal::BlockDevice, begun and then polled. Every poll
// that says Busy calls the wait hook, the one place where time passes while the card works:
// the firmware's hook runs the loop's step when a tick is due (docs/sd-card.md, "the spare-time
// rule"), so a card that holds busy for 250 ms costs the loop nothing.
//
// FatFs calls plain C functions with a drive number, so the card and the hook live in this
// file's one static binding (FatFs is not re-entrant here: FF_FS_REENTRANT 0, one owner).
#pragma once

#include <cstdint>

#include "../../hal/block_device.hpp"

namespace hq {

// What runs while the card is busy. card_busy() is called once per Busy poll; it must not call
// FatFs or the card (it may run a loop step, which never does).
class CardWait {
public:
    virtual void card_busy() = 0;

protected:
    ~CardWait() = default;
};

// Binds drive 0 to `card` (nullptr: no card) and the hook (nullptr: spin on poll()).
void card_disk_attach(BlockDevice* card, CardWait* wait);

// What the card said the last time a transfer did not succeed (Ok when none failed since
// attach): the file layer tells a full or write-protected card from a failed one by it.
BlockStatus card_disk_last_error();

}  // namespace hq

// The port of TinyUSB (firmware/third_party/tinyusb, unmodified) to the Teensy 3.5 image: the
// CMSIS-Core names its Kinetis glue uses, USB0's interrupt handler, and the compile-time proof that
// fsl_device_registers.h and TinyUSB's own register layout (ci_fs_type.h) agree with the MK64F12
// SVD (the generated mk64f12.hpp).
#include <cstddef>

#include "../clock.hpp"
#include "../cpu.hpp"
#include "../mk64f12.hpp"
#include "fsl_device_registers.h"
#include "tusb.h"
#include "portable/chipidea/ci_fs/ci_fs_type.h"

namespace {

namespace mk64 = hq::mk64;
namespace usb = hq::mk64::USB0;

// Below the I2C (10), above SysTick (12): the handler only queues events for tud_task() in
// the loop, so nothing time-critical waits on it (docs/teensy35.md, Interrupts).
constexpr uint8_t kUsbIrqPriority = 11;

static_assert(USB0_BASE == usb::BASE);
static_assert(USB0_IRQn == mk64::irq::USB0);

static_assert(USB_ISTAT_USBRST_MASK == usb::ISTAT::USBRST);
static_assert(USB_ISTAT_ERROR_MASK == usb::ISTAT::ERROR);
static_assert(USB_ISTAT_SOFTOK_MASK == usb::ISTAT::SOFTOK);
static_assert(USB_ISTAT_TOKDNE_MASK == usb::ISTAT::TOKDNE);
static_assert(USB_ISTAT_SLEEP_MASK == usb::ISTAT::SLEEP);
static_assert(USB_ISTAT_RESUME_MASK == usb::ISTAT::RESUME);
static_assert(USB_ISTAT_STALL_MASK == usb::ISTAT::STALL);
static_assert(USB_INTEN_USBRSTEN_MASK == usb::INTEN::USBRSTEN);
static_assert(USB_INTEN_ERROREN_MASK == usb::INTEN::ERROREN);
static_assert(USB_INTEN_TOKDNEEN_MASK == usb::INTEN::TOKDNEEN);
static_assert(USB_INTEN_SLEEPEN_MASK == usb::INTEN::SLEEPEN);
static_assert(USB_INTEN_RESUMEEN_MASK == usb::INTEN::RESUMEEN);
static_assert(USB_INTEN_STALLEN_MASK == usb::INTEN::STALLEN);
static_assert(USB_STAT_ODD_MASK == usb::STAT::ODD);
static_assert(USB_STAT_TX_MASK == usb::STAT::TX);
static_assert(USB_STAT_TX_MASK == 1u << USB_STAT_TX_SHIFT);
static_assert(USB_STAT_ENDP_SHIFT == usb::STAT::ENDP_SHIFT);
static_assert(USB_CTL_USBENSOFEN_MASK == usb::CTL::USBENSOFEN);
static_assert(USB_CTL_ODDRST_MASK == usb::CTL::ODDRST);
static_assert(USB_CTL_RESUME_MASK == usb::CTL::RESUME);
static_assert(USB_CTL_TXSUSPENDTOKENBUSY_MASK == usb::CTL::TXSUSPENDTOKENBUSY);
static_assert(USB_ENDPT_EPHSHK_MASK == usb::ENDPT0::EPHSHK);
static_assert(USB_ENDPT_EPSTALL_MASK == usb::ENDPT0::EPSTALL);
static_assert(USB_ENDPT_EPTXEN_MASK == usb::ENDPT0::EPTXEN);
static_assert(USB_ENDPT_EPRXEN_MASK == usb::ENDPT0::EPRXEN);
static_assert(USB_ENDPT_EPCTLDIS_MASK == usb::ENDPT0::EPCTLDIS);
static_assert(USB_USBCTRL_SUSP_MASK == usb::USBCTRL::SUSP);
static_assert(USB_CONTROL_DPPULLUPNONOTG_MASK == usb::CONTROL::DPPULLUPNONOTG);
static_assert(USB_USBTRC0_USB_RESUME_INT_MASK == usb::USBTRC0::USB_RESUME_INT);
static_assert(USB_USBTRC0_USBRESMEN_MASK == usb::USBTRC0::USBRESMEN);
static_assert(USB_USBTRC0_USBRESET_MASK == usb::USBTRC0::USBRESET);

// TinyUSB's register struct against the SVD's offsets: the driver writes through it.
template <typename Reg>
constexpr size_t offset_of() {
    return Reg::address - usb::BASE;
}
static_assert(offsetof(ci_fs_regs_t, INT_STAT) == offset_of<usb::ISTAT>());
static_assert(offsetof(ci_fs_regs_t, INT_EN) == offset_of<usb::INTEN>());
static_assert(offsetof(ci_fs_regs_t, STAT) == offset_of<usb::STAT>());
static_assert(offsetof(ci_fs_regs_t, CTL) == offset_of<usb::CTL>());
static_assert(offsetof(ci_fs_regs_t, ADDR) == offset_of<usb::ADDR>());
static_assert(offsetof(ci_fs_regs_t, BDT_PAGE1) == offset_of<usb::BDTPAGE1>());
static_assert(offsetof(ci_fs_regs_t, BDT_PAGE2) == offset_of<usb::BDTPAGE2>());
static_assert(offsetof(ci_fs_regs_t, BDT_PAGE3) == offset_of<usb::BDTPAGE3>());
static_assert(offsetof(ci_fs_regs_t, EP) == offset_of<usb::ENDPT0>());
static_assert(offsetof(ci_fs_regs_t, USBCTRL) == offset_of<usb::USBCTRL>());
static_assert(offsetof(ci_fs_regs_t, CONTROL) == offset_of<usb::CONTROL>());
static_assert(offsetof(ci_fs_regs_t, USBTRC0) == offset_of<usb::USBTRC0>());

}  // namespace

extern "C" {

void NVIC_EnableIRQ(int irq) { hq::teensy::nvic_enable(irq, kUsbIrqPriority); }

void NVIC_DisableIRQ(int irq) { hq::teensy::nvic_disable(irq); }

void __DSB() { hq::teensy::dsb(); }

void __NOP() { __asm volatile("nop"); }

// The remote wake-up's resume signal counts SystemCoreClock / 1000 loops (1 ms or more).
const uint32_t SystemCoreClock = hq::teensy::kCoreHz;

// USB0's vector (IRQ 53, startup.cpp): everything is the driver's.
void USB0_IRQHandler() { tud_int_handler(0); }

}  // extern "C"

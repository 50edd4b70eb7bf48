/* What TinyUSB's Kinetis glue (ci_fs_kinetis.h, dcd_ci_fs.c; vendored unmodified) expects
 * from NXP's SDK header of this name, which the project does not use: USB0's base address and
 * IRQ number, the USB0 register bit masks the driver names, and the few CMSIS-Core names it
 * uses (NVIC_EnableIRQ/DisableIRQ, __IO, __DSB, __NOP, SystemCoreClock).
 * C, because the vendored C files include it. The values are those of the MK64F12 SVD:
 * usb_port.cpp checks every one at compile time against the generated mk64f12.hpp. */
#ifndef HQ_TEENSY35_FSL_DEVICE_REGISTERS_H
#define HQ_TEENSY35_FSL_DEVICE_REGISTERS_H

#ifdef __cplusplus
extern "C" {
#endif

#define USB0_BASE 0x40072000u /* SVD: USB0 baseAddress */
#define USB0_IRQn 53          /* SVD: interrupt USB0 */

#include <stdint.h>

/* The CMSIS-Core names, on the project's own code (usb_port.cpp, cpu.hpp, clock.hpp). */
#define __IO volatile
void NVIC_EnableIRQ(int irq);
void NVIC_DisableIRQ(int irq);
void __DSB(void);
void __NOP(void);
extern const uint32_t SystemCoreClock; /* Hz, after start_clocks() */

/* USB0 register fields, as masks (SVD field bit offsets). */
#define USB_ISTAT_USBRST_MASK (1u << 0)
#define USB_ISTAT_ERROR_MASK (1u << 1)
#define USB_ISTAT_SOFTOK_MASK (1u << 2)
#define USB_ISTAT_TOKDNE_MASK (1u << 3)
#define USB_ISTAT_SLEEP_MASK (1u << 4)
#define USB_ISTAT_RESUME_MASK (1u << 5)
#define USB_ISTAT_STALL_MASK (1u << 7)

#define USB_INTEN_USBRSTEN_MASK (1u << 0)
#define USB_INTEN_ERROREN_MASK (1u << 1)
#define USB_INTEN_TOKDNEEN_MASK (1u << 3)
#define USB_INTEN_SLEEPEN_MASK (1u << 4)
#define USB_INTEN_RESUMEEN_MASK (1u << 5)
#define USB_INTEN_STALLEN_MASK (1u << 7)

#define USB_STAT_ODD_MASK (1u << 2)
#define USB_STAT_TX_MASK (1u << 3)
#define USB_STAT_TX_SHIFT 3
#define USB_STAT_ENDP_SHIFT 4

#define USB_CTL_USBENSOFEN_MASK (1u << 0)
#define USB_CTL_ODDRST_MASK (1u << 1)
#define USB_CTL_RESUME_MASK (1u << 2)
#define USB_CTL_TXSUSPENDTOKENBUSY_MASK (1u << 5)

#define USB_ENDPT_EPHSHK_MASK (1u << 0)
#define USB_ENDPT_EPSTALL_MASK (1u << 1)
#define USB_ENDPT_EPTXEN_MASK (1u << 2)
#define USB_ENDPT_EPRXEN_MASK (1u << 3)
#define USB_ENDPT_EPCTLDIS_MASK (1u << 4)

#define USB_USBCTRL_SUSP_MASK (1u << 7)
#define USB_CONTROL_DPPULLUPNONOTG_MASK (1u << 4)

#define USB_USBTRC0_USB_RESUME_INT_MASK (1u << 0)
#define USB_USBTRC0_USBRESMEN_MASK (1u << 5)
#define USB_USBTRC0_USBRESET_MASK (1u << 7)

#ifdef __cplusplus
}
#endif

#endif

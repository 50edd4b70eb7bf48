/* TinyUSB's configuration for the Teensy 3.5 image (firmware/third_party/tinyusb, unmodified,
 * includes this header by name): device only, no RTOS, one CDC-ACM interface with 64-byte
 * endpoints on the MK64's full-speed USB0. C, because the vendored C files include it. */
#ifndef HQ_TEENSY35_TUSB_CONFIG_H
#define HQ_TEENSY35_TUSB_CONFIG_H

/* OPT_MCU_KINETIS_K: the MK64FX512 is a Kinetis K part; in TinyUSB 0.21.0's tusb_mcu.h it
 * selects TUP_USBIP_CHIPIDEA_FS_KINETIS, the ci_fs driver with its Kinetis glue
 * (ci_fs_kinetis.h), like OPT_MCU_KINETIS_KL (the old OPT_MCU_MKL25ZXX) does. */
#define CFG_TUSB_MCU OPT_MCU_KINETIS_K
#define CFG_TUSB_OS OPT_OS_NONE
#define CFG_TUSB_DEBUG 0

/* Root port 0 is the device, full speed (the MK64's USB0 has no high-speed PHY). */
#define CFG_TUD_ENABLED 1
#define CFG_TUD_MAX_SPEED OPT_MODE_FULL_SPEED
#define CFG_TUH_ENABLED 0

/* The controller's buffer descriptors and buffers: ordinary SRAM, 4-byte aligned (the
 * driver itself aligns its buffer descriptor table to 512 bytes). */
#define CFG_TUD_MEM_SECTION
#define CFG_TUD_MEM_ALIGN __attribute__((aligned(4)))

/* Full-speed control endpoint: 64 bytes (USB 2.0, 5.5.3: 8, 16, 32 or 64 at full speed). */
#define CFG_TUD_ENDPOINT0_SIZE 64

/* One CDC-ACM interface and no other class. */
#define CFG_TUD_CDC 1
#define CFG_TUD_MSC 0
#define CFG_TUD_HID 0
#define CFG_TUD_MIDI 0
#define CFG_TUD_VENDOR 0

/* 64-byte bulk packets (the full-speed maximum, USB 2.0, 5.8.3). Transmit: a 1 KiB buffer (three loops of telemetry)
 * (the loop's messages go in whole or not at all, usb_serial.hpp) sent in transfers of up to
 * 512 bytes, eight packets the driver queues from its interrupt; a message never
 * overwrites an older one, even while no host has the port open (the port layer lets the
 * bytes go instead). Receive: 256 bytes, four packets; while fewer than a packet's 64 bytes
 * are free the stack queues no OUT transfer, so the controller NAKs the host's next packet
 * (USB's own flow control): a ground station's burst of parameter writes waits, never lost. */
#define CFG_TUD_CDC_RX_EPSIZE 64
#define CFG_TUD_CDC_TX_EPSIZE 512
#define CFG_TUD_CDC_RX_BUFSIZE 256
#define CFG_TUD_CDC_TX_BUFSIZE 1024
#define CFG_TUD_CDC_TX_OVERWRITABLE_IF_NOT_CONNECTED 0

#endif

/* FatFs's configuration for heliquad (the vendored FatFs is firmware/third_party/fatfs/, this
 * file is ours: ff.h includes "ffconf.h" and finds it on the include path). One log file open
 * at a time on one card, written in the loop's spare time by one owner (docs/sd-card.md).
 * Every option ff.h reads is set here; the values and why: */
#define FFCONF_DEF 80286 /* the revision of FatFs this file is written for (R0.15) */

/* Functions. Read/write; the full API (level 0) because the file layer uses f_mkdir,
 * f_unlink (erasing the logs), the directory reads (numbering and listing) and f_lseek (the
 * log protocol's reads at an offset); the linker drops what nobody calls. */
#define FF_FS_READONLY 0
#define FF_FS_MINIMIZE 0
#define FF_USE_FIND 0     /* the directory is read entry by entry */
/* f_mkfs: only where a card image is made (the host build and its bindings: `heliquad
 * sd-image`, a fresh --sd-image); the Teensy never formats its card. CMake sets
 * HQ_FATFS_MKFS=1 for those builds. */
#ifndef HQ_FATFS_MKFS
#define HQ_FATFS_MKFS 0
#endif
#define FF_USE_MKFS HQ_FATFS_MKFS
#define FF_USE_FASTSEEK 0 /* reads go forward through a log; no cluster map in RAM */
#define FF_USE_EXPAND 0   /* logs grow as they are written; nothing is allocated ahead */
#define FF_USE_CHMOD 0
#define FF_USE_LABEL 0
#define FF_USE_FORWARD 0
#define FF_USE_STRFUNC 0  /* LASTLOG.TXT is formatted by the file layer itself */
#define FF_PRINT_LLI 0
#define FF_PRINT_FLOAT 0
#define FF_STRF_ENCODE 0

/* Names: 8.3 only (LOGS/00000001.BIN, LASTLOG.TXT), so no long file names and none of
 * ffunicode.c's tables. Code page 437 (US) is the one ff.c's own up-case table covers for the
 * bytes 0x80-0xFF of a name; ours are ASCII. No relative paths (every path is absolute). */
#define FF_CODE_PAGE 437
#define FF_USE_LFN 0
#define FF_MAX_LFN 255
#define FF_LFN_UNICODE 0
#define FF_LFN_BUF 255
#define FF_SFN_BUF 12
#define FF_FS_RPATH 0

/* The drive: one card, one volume, found by FatFs's own search (a FAT boot sector at block 0,
 * or the first FAT partition of an MBR). 512-byte blocks (hal/block_device.hpp); 32-bit block
 * numbers reach 2 TiB, more than an SDHC or SDXC card has; no TRIM. */
#define FF_VOLUMES 1
#define FF_STR_VOLUME_ID 0
#define FF_VOLUME_STRS "SD"
#define FF_MULTI_PARTITION 0
#define FF_MIN_SS 512
#define FF_MAX_SS 512
#define FF_LBA64 0
#define FF_MIN_GPT 0x10000000
#define FF_USE_TRIM 0

/* System. Tiny: the file's data goes through the volume's one 512-byte window, not a second
 * buffer per file (512 bytes of RAM saved on the Teensy). FAT12/16/32 only: exFAT (SDXC's
 * factory format) is refused as a failed card; reformat it FAT32. No clock on the board: every
 * file is stamped 1980-01-01, the FAT epoch (the log protocol reports time 0, "unknown").
 * FSINFO's free count is trusted for speed but never needed for correctness. One owner of the
 * card (the spare-time service), so no file locks and no re-entrancy. */
#define FF_FS_TINY 1
#define FF_FS_EXFAT 0
#define FF_FS_NORTC 1
#define FF_NORTC_MON 1
#define FF_NORTC_MDAY 1
#define FF_NORTC_YEAR 1980
#define FF_FS_NOFSINFO 0
#define FF_FS_LOCK 0
#define FF_FS_REENTRANT 0
#define FF_FS_TIMEOUT 1000

// The logs as files on the card (log_files.hpp).
#include "log_files.hpp"

namespace hq {
namespace {

constexpr char kLogDir[] = "/LOGS";
constexpr char kLastLog[] = "/LASTLOG.TXT";
constexpr uint16_t kMaxLogId = 0xFFFF;   // LogInfo::id is 16 bits (the protocol's log id)
constexpr UINT kLastLogMaxBytes = 16;    // "65535\r\n" and room for a damaged longer file
// "/LOGS/" + 8 digits + ".BIN" + NUL.
constexpr int kPathChars = 6 + 8 + 4 + 1;

// "/LOGS/00000042.BIN" for id 42.
void log_path(uint16_t id, char (&path)[kPathChars]) {
    const char head[] = "/LOGS/";
    int at = 0;
    for (const char* c = head; *c != '\0'; ++c) path[at++] = *c;
    uint32_t v = id;
    for (int d = 7; d >= 0; --d) {
        path[at + d] = static_cast<char>('0' + v % 10);
        v /= 10;
    }
    at += 8;
    for (const char* c = ".BIN"; *c != '\0'; ++c) path[at++] = *c;
    path[at] = '\0';
}

// A log's number from its 8.3 name ("00000042.BIN"), 0 when the name is not a log's.
uint16_t log_id(const char* name) {
    uint32_t v = 0;
    for (int i = 0; i < 8; ++i) {
        if (name[i] < '0' || name[i] > '9') return 0;
        v = v * 10 + static_cast<uint32_t>(name[i] - '0');
    }
    const char ext[] = ".BIN";
    for (int i = 0; i < 5; ++i) {
        if (name[8 + i] != ext[i]) return 0;   // the NUL included: nothing after .BIN
    }
    return v <= kMaxLogId ? static_cast<uint16_t>(v) : 0;
}

// LASTLOG.TXT's number: decimal digits, then only CR, LF or spaces; 0 when damaged.
uint16_t parse_lastlog(const char* text, UINT n) {
    uint32_t v = 0;
    UINT i = 0;
    for (; i < n && text[i] >= '0' && text[i] <= '9'; ++i) {
        v = v * 10 + static_cast<uint32_t>(text[i] - '0');
        if (v > kMaxLogId) return 0;
    }
    if (i == 0) return 0;
    for (; i < n; ++i) {
        if (text[i] != '\r' && text[i] != '\n' && text[i] != ' ') return 0;
    }
    return static_cast<uint16_t>(v);
}

}  // namespace

LogFiles::~LogFiles() {
    end_log();
    close();
    if (mounted_) f_unmount("");
    card_disk_attach(nullptr, nullptr);
}

CardState LogFiles::mount() {
    card_disk_attach(&card_, wait_);
    const FRESULT res = f_mount(&fs_, "", 1);
    if (res != FR_OK) {
        // No answer is no card; anything else (no FAT volume, a card too small to hold one,
        // a read that failed) is a failed card.
        state_ = res == FR_NOT_READY ? CardState::NoCard : CardState::Failed;
        return state_;
    }
    mounted_ = true;
    state_ = card_.write_protected() ? CardState::WriteProtected : CardState::Ok;
    if (state_ == CardState::Ok) {
        const FRESULT made = f_mkdir(kLogDir);
        if (made != FR_OK && made != FR_EXIST) fail(made);
    }
    const uint16_t lastlog = read_lastlog();
    const uint16_t largest = largest_log();
    last_ = lastlog > largest ? lastlog : largest;
    return state_;
}

bool LogFiles::begin_log() {
    end_log();
    close();
    if (state_ != CardState::Ok) return false;
    if (last_ == kMaxLogId) {
        state_ = CardState::Full;       // no number left for another log
        return false;
    }
    const uint16_t id = static_cast<uint16_t>(last_ + 1);
    char path[kPathChars];
    log_path(id, path);
    FRESULT res = f_open(&file_, path, FA_WRITE | FA_CREATE_ALWAYS);
    if (res != FR_OK) {
        fail(res);
        return false;
    }
    mode_ = Mode::Writing;
    last_ = id;
    res = f_sync(&file_);               // the directory entry on the card before any data
    if (res != FR_OK || !write_lastlog(id)) {
        if (res != FR_OK) fail(res);
        close();
        return false;
    }
    unsynced_ = false;
    return true;
}

uint32_t LogFiles::write(const uint8_t* data, uint32_t n) {
    if (mode_ != Mode::Writing || state_ != CardState::Ok || n == 0) return 0;
    UINT taken = 0;
    const FRESULT res = f_write(&file_, data, n, &taken);
    if (taken > 0 && !unsynced_) {
        unsynced_ = true;
        unsynced_since_us_ = clock_.micros();
    }
    if (res != FR_OK) {
        fail(res);
    } else if (taken < n) {
        state_ = CardState::Full;       // FatFs found no free cluster
        sync();
    } else {
        service();
    }
    return taken;
}

void LogFiles::service() {
    // Half the period: a service that runs every loop meets the period with room for the
    // sync's own time on a busy card.
    if (mode_ == Mode::Writing && unsynced_ &&
        clock_.micros() - unsynced_since_us_ >= LogSink::kSyncPeriodUs / 2) {
        sync();
    }
}

void LogFiles::end_log() {
    if (mode_ != Mode::Writing) return;
    sync();
    close();
}

bool LogFiles::sync() {
    unsynced_ = false;
    const FRESULT res = f_sync(&file_);
    if (res == FR_OK) return true;
    fail(res);
    return false;
}

void LogFiles::close() {
    if (mode_ != Mode::Closed) f_close(&file_);   // a failed file's close changes nothing
    mode_ = Mode::Closed;
}

void LogFiles::fail(FRESULT res) {
    state_ = state_of(res);
    close();
}

CardState LogFiles::state_of(FRESULT res) const {
    switch (res) {
        case FR_WRITE_PROTECTED: return CardState::WriteProtected;
        case FR_DENIED: return CardState::Full;               // no room for a file or a cluster
        case FR_NOT_READY: return CardState::NoCard;
        case FR_DISK_ERR:
            switch (card_disk_last_error()) {
                case BlockStatus::OutOfRange: return CardState::Full;   // refused past its end
                case BlockStatus::WriteProtected: return CardState::WriteProtected;
                case BlockStatus::NoCard: return CardState::NoCard;
                default: return CardState::Failed;
            }
        default: return CardState::Failed;
    }
}

uint16_t LogFiles::read_lastlog() {
    FIL f{};
    if (f_open(&f, kLastLog, FA_READ) != FR_OK) return 0;
    char text[kLastLogMaxBytes];
    UINT n = 0;
    const FRESULT res = f_read(&f, text, sizeof text, &n);
    f_close(&f);
    return res == FR_OK ? parse_lastlog(text, n) : 0;
}

bool LogFiles::write_lastlog(uint16_t id) {
    char text[8];
    int at = 0;
    char digits[5];
    int nd = 0;
    for (uint32_t v = id; v != 0 || nd == 0; v /= 10) digits[nd++] = static_cast<char>('0' + v % 10);
    while (nd > 0) text[at++] = digits[--nd];
    text[at++] = '\r';
    text[at++] = '\n';
    FIL f{};
    FRESULT res = f_open(&f, kLastLog, FA_WRITE | FA_CREATE_ALWAYS);
    UINT written = 0;
    if (res == FR_OK) res = f_write(&f, text, static_cast<UINT>(at), &written);
    const FRESULT closed = f_close(&f);
    if (res == FR_OK) res = closed;
    if (res == FR_OK && written != static_cast<UINT>(at)) res = FR_DENIED;
    if (res != FR_OK) fail(res);
    return res == FR_OK;
}

bool LogFiles::next_log(uint16_t after_id, LogInfo& out) {
    DIR dir{};
    if (!mounted_ || f_opendir(&dir, kLogDir) != FR_OK) return false;
    bool found = false;
    FILINFO fno{};
    while (f_readdir(&dir, &fno) == FR_OK && fno.fname[0] != '\0') {
        if ((fno.fattrib & AM_DIR) != 0) continue;
        const uint16_t id = log_id(fno.fname);
        if (id == 0 || id <= after_id || (found && id >= out.id)) continue;
        found = true;
        out.id = id;
        out.size_bytes = static_cast<uint32_t>(fno.fsize);
        out.time_utc_s = 0;             // no clock on the board (FF_FS_NORTC)
    }
    f_closedir(&dir);
    return found;
}

uint16_t LogFiles::largest_log() {
    uint16_t largest = 0;
    LogInfo info;
    for (uint16_t after = 0; next_log(after, info); after = info.id) largest = info.id;
    return largest;
}

uint16_t LogFiles::count() {
    if (mode_ == Mode::Writing) return 0;    // served disarmed only: no log is open then
    uint16_t n = 0;
    LogInfo info;
    for (uint16_t after = 0; next_log(after, info); after = info.id) ++n;
    return n;
}

bool LogFiles::info(uint16_t index, LogInfo& out) {
    if (mode_ == Mode::Writing) return false;
    // A listing asks for 0, 1, 2, ...: it goes on from the last answer instead of the start.
    uint16_t i = 0, after = 0;
    if (listed_id_ != 0 && index > listed_index_) {
        i = static_cast<uint16_t>(listed_index_ + 1);
        after = listed_id_;
    }
    for (; next_log(after, out); ++i, after = out.id) {
        if (i == index) {
            listed_index_ = index;
            listed_id_ = out.id;
            return true;
        }
    }
    return false;
}

int32_t LogFiles::read(uint16_t id, uint32_t offset, uint8_t* data, uint32_t n) {
    if (!mounted_ || mode_ == Mode::Writing || id == 0) return -1;
    if (mode_ != Mode::Reading || reading_id_ != id) {
        close();
        char path[kPathChars];
        log_path(id, path);
        if (f_open(&file_, path, FA_READ) != FR_OK) return -1;
        mode_ = Mode::Reading;
        reading_id_ = id;
    }
    if (f_tell(&file_) != offset && f_lseek(&file_, offset) != FR_OK) {
        close();
        return -1;
    }
    UINT got = 0;
    if (f_read(&file_, data, n, &got) != FR_OK) {
        close();
        return -1;
    }
    return static_cast<int32_t>(got);
}

bool LogFiles::erase_all() {
    if (!mounted_ || mode_ == Mode::Writing) return false;
    close();
    listed_id_ = 0;
    LogInfo info;
    char path[kPathChars];
    while (next_log(0, info)) {
        log_path(info.id, path);
        const FRESULT res = f_unlink(path);
        if (res != FR_OK) return false;
    }
    const FRESULT res = f_unlink(kLastLog);
    if (res != FR_OK && res != FR_NO_FILE) return false;
    last_ = 0;
    if (state_ == CardState::Full) state_ = CardState::Ok;   // the room is back
    return true;
}

}  // namespace hq

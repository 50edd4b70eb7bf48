// RamLogStore: a folder's .BIN files as the log protocol's logs (ram_log_store.hpp).
#include "ram_log_store.hpp"

#include <dirent.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>

namespace hq {

namespace {

constexpr size_t kNumberDigits = 8;          // LOGS/00000001.BIN
constexpr uint32_t kMaxLogBytes = 0x7fffffff;  // read() answers in an int32_t

bool is_log_name(const std::string& name) {
    if (name.size() < 5) return false;
    std::string ext = name.substr(name.size() - 4);
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::toupper(c); });
    return ext == ".BIN";
}

// The card's number in a name like 00000001.BIN, else 0.
uint16_t card_number(const std::string& name) {
    if (name.size() != kNumberDigits + 4) return 0;
    unsigned long v = 0;
    for (size_t i = 0; i < kNumberDigits; ++i) {
        if (name[i] < '0' || name[i] > '9') return 0;
        v = v * 10 + static_cast<unsigned long>(name[i] - '0');
    }
    return v <= UINT16_MAX ? static_cast<uint16_t>(v) : 0;
}

}  // namespace

bool RamLogStore::load(const std::string& folder, std::string& error) {
    DIR* dir = opendir(folder.c_str());
    if (dir == nullptr) {
        error = "cannot read log folder " + folder + ": " + std::strerror(errno);
        return false;
    }
    std::vector<std::string> names;
    while (const dirent* e = readdir(dir)) {
        if (is_log_name(e->d_name)) names.push_back(e->d_name);
    }
    closedir(dir);
    std::sort(names.begin(), names.end());
    uint16_t next = 1;
    for (const std::string& name : names) next = std::max<uint16_t>(next, static_cast<uint16_t>(card_number(name) + 1));
    for (const std::string& name : names) {
        const std::string path = folder + "/" + name;
        std::ifstream f(path, std::ios::binary);
        struct stat st {};
        if (!f || stat(path.c_str(), &st) != 0 || st.st_size > kMaxLogBytes) {
            error = "cannot read log " + path;
            return false;
        }
        Log log;
        log.bytes.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
        const uint16_t number = card_number(name);
        log.info.id = number != 0 ? number : next++;
        log.info.size_bytes = static_cast<uint32_t>(log.bytes.size());
        log.info.time_utc_s = static_cast<uint32_t>(st.st_mtime);
        logs_.push_back(std::move(log));
    }
    std::sort(logs_.begin(), logs_.end(), [](const Log& a, const Log& b) { return a.info.id < b.info.id; });
    return true;
}

bool RamLogStore::info(uint16_t index, LogInfo& out) {
    if (index >= logs_.size()) return false;
    out = logs_[index].info;
    return true;
}

int32_t RamLogStore::read(uint16_t id, uint32_t offset, uint8_t* data, uint32_t n) {
    for (const Log& log : logs_) {
        if (log.info.id != id) continue;
        if (offset >= log.bytes.size()) return 0;
        const uint32_t got = std::min<uint32_t>(n, static_cast<uint32_t>(log.bytes.size() - offset));
        std::memcpy(data, log.bytes.data() + offset, got);
        return static_cast<int32_t>(got);
    }
    return -1;
}

bool RamLogStore::erase_all() {
    logs_.clear();
    return true;
}

}  // namespace hq

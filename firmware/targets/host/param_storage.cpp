#include "param_storage.hpp"

#include <cerrno>
#include <cstdio>
#include <fcntl.h>
#include <unistd.h>

namespace hq {

StoreStatus FileParamStorage::load(uint8_t* data, size_t capacity, size_t& n) {
    n = 0;
    const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return errno == ENOENT ? StoreStatus::Empty : StoreStatus::Corrupt;
    bool ok = true;
    for (;;) {
        if (n == capacity) {                 // larger than any record: not one of ours
            uint8_t extra;
            ok = ::read(fd, &extra, 1) == 0;
            break;
        }
        const ssize_t got = ::read(fd, data + n, capacity - n);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) {
            ok = got == 0;
            break;
        }
        n += static_cast<size_t>(got);
    }
    ::close(fd);
    if (!ok) {
        n = 0;
        return StoreStatus::Corrupt;
    }
    return n == 0 ? StoreStatus::Corrupt : StoreStatus::Ok;    // an empty file is damage
}

bool FileParamStorage::save(const uint8_t* data, size_t n) {
    const std::string tmp = path_ + ".tmp";
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) return false;
    size_t done = 0;
    while (done < n) {
        const ssize_t w = ::write(fd, data + done, n - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) break;
        done += static_cast<size_t>(w);
    }
    const bool written = done == n && ::fsync(fd) == 0;
    const bool closed = ::close(fd) == 0;
    if (!(written && closed) || std::rename(tmp.c_str(), path_.c_str()) != 0) {
        ::unlink(tmp.c_str());
        return false;
    }
    return true;
}

}  // namespace hq

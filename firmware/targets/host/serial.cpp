#include "serial.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <time.h>
#include <termios.h>
#include <unistd.h>

namespace hq {

bool PtySerial::open(const std::string& link_path) {
    master_ = posix_openpt(O_RDWR | O_NOCTTY);
    if (master_ < 0 || grantpt(master_) != 0 || unlockpt(master_) != 0) {
        error_ = std::string("cannot create a pty: ") + std::strerror(errno);
        return false;
    }
    const char* name = ptsname(master_);
    if (name == nullptr) {
        error_ = "ptsname failed";
        return false;
    }
    slave_path_ = name;
    // Keep a slave descriptor open: the master then never sees EOF/EIO while the peer is
    // between opens, and we can put the line into raw mode before anyone uses it.
    slave_ = ::open(name, O_RDWR | O_NOCTTY);
    if (slave_ < 0) {
        error_ = std::string("cannot open ") + name + ": " + std::strerror(errno);
        return false;
    }
    termios tio{};
    tcgetattr(slave_, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave_, TCSANOW, &tio);
    fcntl(master_, F_SETFL, fcntl(master_, F_GETFL) | O_NONBLOCK);
    // Our own slave descriptor reads only to drop the oldest bytes (drop_oldest): never wait.
    fcntl(slave_, F_SETFL, fcntl(slave_, F_GETFL) | O_NONBLOCK);
    link_path_ = link_path;
    ::unlink(link_path.c_str());
    if (::symlink(name, link_path.c_str()) != 0) {
        error_ = "cannot create " + link_path + ": " + std::strerror(errno);
        return false;
    }
    return true;
}

void PtySerial::close() {
    if (!link_path_.empty()) ::unlink(link_path_.c_str());
    link_path_.clear();
    if (slave_ >= 0) ::close(slave_);
    if (master_ >= 0) ::close(master_);
    slave_ = master_ = -1;
}

size_t PtySerial::read(uint8_t* data, size_t n) {
    // A poll that just found no input saves the loop a system call per step.
    if (!maybe_input_) return 0;
    const ssize_t r = ::read(master_, data, n);
    if (r <= 0) maybe_input_ = false;
    return r > 0 ? static_cast<size_t>(r) : 0;
}

size_t PtySerial::write(const uint8_t* data, size_t n) {
    if (n > kBufferSize - count_) return 0;   // full: the whole message is dropped
    for (size_t i = 0; i < n; ++i) buf_[(head_ + count_ + i) % kBufferSize] = data[i];
    count_ += n;
    return n;
}

void PtySerial::drop_oldest() {
    int waiting = 0;                          // what no reader has taken from the pty yet
    if (::ioctl(slave_, TIOCINQ, &waiting) != 0 || waiting < 0) waiting = 0;
    const size_t total = static_cast<size_t>(waiting) + count_;
    if (total <= backlog_limit_) return;
    size_t excess = total - backlog_limit_;
    uint8_t scrap[512];
    while (excess > 0 && waiting > 0) {       // the oldest first: those in the pty
        const size_t want = excess < sizeof(scrap) ? excess : sizeof(scrap);
        const ssize_t r = ::read(slave_, scrap, want);
        if (r <= 0) break;                    // a reader took them meanwhile
        excess -= static_cast<size_t>(r);
        waiting -= static_cast<int>(r);
        discarded_ += static_cast<size_t>(r);
    }
    if (excess > count_) excess = count_;     // then the front of this buffer
    head_ = (head_ + excess) % kBufferSize;
    count_ -= excess;
    discarded_ += excess;
}

bool PtySerial::flush() {
    if (backlog_limit_ > 0) drop_oldest();
    while (count_ > 0) {
        const size_t chunk = head_ + count_ <= kBufferSize ? count_ : kBufferSize - head_;
        const ssize_t w = ::write(master_, buf_ + head_, chunk);
        if (w < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
        head_ = (head_ + static_cast<size_t>(w)) % kBufferSize;
        count_ -= static_cast<size_t>(w);
        if (static_cast<size_t>(w) < chunk) return true;   // the pty is full for now
    }
    return true;
}

bool PtySerial::wait_readable_us(long timeout_us, PtySerial* also) {
    pollfd p[2] = {{master_, POLLIN, 0}, {also ? also->master_ : -1, POLLIN, 0}};
    const timespec t{timeout_us / 1000000, (timeout_us % 1000000) * 1000};
    const int r = ::ppoll(p, also ? 2 : 1, &t, nullptr);
    if (also) also->maybe_input_ = r > 0 && (p[1].revents & POLLIN);
    return r > 0 && (p[0].revents & POLLIN);
}

bool PtySerial::write_all(const uint8_t* data, size_t n, int timeout_ms) {
    size_t done = 0;
    while (done < n) {
        const ssize_t w = ::write(master_, data + done, n - done);
        if (w > 0) {
            done += static_cast<size_t>(w);
            continue;
        }
        if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return false;
        pollfd p{master_, POLLOUT, 0};
        if (::poll(&p, 1, timeout_ms) <= 0) return false;
    }
    return true;
}

}  // namespace hq

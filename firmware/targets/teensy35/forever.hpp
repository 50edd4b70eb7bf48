// An object built once in static storage and never destroyed: for the image's long-lived
// objects whose class has a destructor (the host build needs it: the file layer closes its
// file there). A function-local `static T` of such a class would register that destructor to
// run at exit (__cxa_atexit, __dso_handle), which a bare-metal image that never exits does not
// link; here the storage is static, the object is placement-constructed, and nothing runs at
// exit. No heap: placement new only.
#pragma once

#include <new>
#include <utility>

namespace hq::teensy {

template <typename T>
class Forever {
public:
    template <typename... Args>
    explicit Forever(Args&&... args) {
        ::new (static_cast<void*>(storage_)) T(std::forward<Args>(args)...);
    }
    Forever(const Forever&) = delete;
    Forever& operator=(const Forever&) = delete;

    T& get() { return *std::launder(reinterpret_cast<T*>(storage_)); }

private:
    alignas(T) unsigned char storage_[sizeof(T)];
};

}  // namespace hq::teensy

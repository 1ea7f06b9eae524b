// The memory of the bindings' output arrays, reused.  glibc maps a block of 32 MiB or more (and
// of less, until a free raises its threshold) fresh from the kernel and gives it back when it is
// freed, so each new array's pages were faulted in and zeroed again by the kernel on first
// touch: 14 % of a sampler check's time at 1e6 samples under perf (its uniforms, parameters,
// flags and pdf values are new arrays of 1-16 MB on every call; raising glibc's mmap and trim
// thresholds, which a library must not do to its whole process, took a check of a GGX sampler
// from 37-49 ms to 28 ms).  With this cache the kernel's zeroing fell to 1 % and the check's
// median from 56-58 ms to 34-47 ms (alternated runs, the sampler's own time included).  Here a
// freed buffer of at least 1 MiB goes to a small cache instead (at most 8 buffers and 256 MiB in
// all, none over 128 MiB), and the next array that fits it (at most twice its size) takes it,
// its pages already mapped.  Contents are never relied on: the arrays are written before use.
#pragma once

#include <sys/mman.h>  // madvise: huge pages under big arrays

#include <cstddef>
#include <cstdint>
#include <mutex>
#include <new>
#include <utility>
#include <vector>

namespace re {

// Asks the kernel for transparent huge pages under a new buffer of `bytes` from 4 MiB (what
// numpy does for its own arrays): a million 3-vectors are 24 MB, 6000 page faults of 4 KiB
// without it, 11 ms of this VM's time a fresh array (as long as the computation filling
// it), and 12 with it.  Only advice: where THP is off it changes nothing.
inline void advise_huge_pages(void *p, size_t bytes) {
    if (bytes < (size_t(1) << 22)) return;
    const uintptr_t first = (reinterpret_cast<uintptr_t>(p) + 4095) & ~uintptr_t(4095);
    const uintptr_t end = reinterpret_cast<uintptr_t>(p) + bytes;
    if (end > first) madvise(reinterpret_cast<void *>(first), end - first, MADV_HUGEPAGE);
}

class BufferCache {
  public:
    // One per process (an inline function's static), never destroyed: numpy may free arrays
    // during the interpreter's shutdown, after static destructors would have run.
    static BufferCache &instance() {
        static BufferCache *cache = new BufferCache;
        return *cache;
    }

    // At least `bytes` bytes, aligned to 64: a cached buffer of at most twice that, or a new one
    // (`capacity` says which size it has, for give()).
    void *take(size_t bytes, size_t &capacity) {
        if (bytes >= kMinBytes) {
            std::lock_guard<std::mutex> lock(mutex_);
            size_t best = free_.size();
            for (size_t i = 0; i < free_.size(); ++i)
                if (free_[i].second >= bytes && free_[i].second <= 2 * bytes &&
                    (best == free_.size() || free_[i].second < free_[best].second))
                    best = i;
            if (best < free_.size()) {
                auto [p, size] = free_[best];
                free_.erase(free_.begin() + std::ptrdiff_t(best));
                cached_ -= size;
                capacity = size;
                return p;
            }
        }
        capacity = bytes > 0 ? bytes : 1;
        void *p = ::operator new(capacity, std::align_val_t(kAlign));
        advise_huge_pages(p, capacity);   // once, where the memory is new
        return p;
    }

    // A buffer from take() back: kept for reuse when it is large enough and fits the cache
    // (the oldest buffers make room), else freed.
    void give(void *p, size_t capacity) noexcept {
        if (capacity >= kMinBytes && capacity <= kMaxOneBytes) {
            std::lock_guard<std::mutex> lock(mutex_);
            while (!free_.empty() && (free_.size() >= kMaxBuffers || cached_ + capacity > kMaxBytes)) {
                release(free_.front().first);
                cached_ -= free_.front().second;
                free_.erase(free_.begin());
            }
            free_.emplace_back(p, capacity);
            cached_ += capacity;
            return;
        }
        release(p);
    }

  private:
    static constexpr size_t kAlign = 64, kMinBytes = size_t(1) << 20, kMaxOneBytes = size_t(128) << 20,
                            kMaxBytes = size_t(256) << 20, kMaxBuffers = 8;
    static void release(void *p) noexcept { ::operator delete(p, std::align_val_t(kAlign)); }

    std::mutex mutex_;
    std::vector<std::pair<void *, size_t>> free_;   // oldest first
    size_t cached_ = 0;
};

}  // namespace re

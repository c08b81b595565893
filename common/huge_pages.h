// Large, long-lived buffers backed by transparent huge pages. Every 4 KiB page a process first
// touches costs a page fault (about 7 µs on the paravirtualised VMs this runs on): the 1080p flat
// image alone is 10 K of them, taken serially before the first bucket starts. A 2 MiB page takes
// one. The kernel honours the advice where THP is "madvise" or "always"; elsewhere it is a no-op,
// and the memory behaves as any other.
#pragma once

#include <cstddef>
#include <new>
#include <vector>

namespace reshutter {

inline constexpr size_t kHugePageBytes = size_t(2) << 20;

/// Asks the kernel to back the whole 2 MiB pages inside [p, p + bytes) with huge pages when they
/// are first touched. Harmless on memory already touched, or where huge pages are off.
void adviseHugePages(const void* p, size_t bytes);

/// An allocator that starts blocks of two huge pages or more on a huge-page boundary and advises
/// them, so that every whole 2 MiB of the block is one fault (a block only malloc-aligned loses
/// a huge page's worth at each end). Smaller blocks come from the ordinary heap.
template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}

  static bool huge(size_t n) { return n * sizeof(T) >= 2 * kHugePageBytes; }
  T* allocate(size_t n) {
    if (!huge(n)) return std::allocator<T>().allocate(n);
    void* p = ::operator new(n * sizeof(T), std::align_val_t(kHugePageBytes));
    adviseHugePages(p, n * sizeof(T));
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) noexcept {
    if (!huge(n)) return std::allocator<T>().deallocate(p, n);
    ::operator delete(p, std::align_val_t(kHugePageBytes));
  }
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }
};

/// A vector whose large storage is huge-paged (HugePageAllocator).
template <class T>
using HugePagedVector = std::vector<T, HugePageAllocator<T>>;

}  // namespace reshutter

// HausdorffOptions::max_bytes against the memory the computation really takes: this program
// counts every allocation made through operator new (the library's tables are std::vectors), so
// it has its own executable.
#include "core/hausdorff.h"

#include <catch2/catch.hpp>

#include <malloc.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace {

std::atomic<int64_t> g_live{0}, g_peak{0};

void* counted(size_t n) {
  void* p = std::malloc(n > 0 ? n : 1);
  if (p == nullptr) throw std::bad_alloc();
  const int64_t now = g_live += static_cast<int64_t>(malloc_usable_size(p));
  int64_t peak = g_peak.load();
  while (now > peak && !g_peak.compare_exchange_weak(peak, now)) {
  }
  return p;
}

void uncounted(void* p) {
  if (p == nullptr) return;
  g_live -= static_cast<int64_t>(malloc_usable_size(p));
  std::free(p);
}

}  // namespace

// Every unaligned form, so that each delete meets its own new (under AddressSanitizer too; the
// aligned forms are left to the library, which pairs them itself).
void* operator new(size_t n) { return counted(n); }
void* operator new[](size_t n) { return counted(n); }
void* operator new(size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted(n);
  } catch (const std::bad_alloc&) {
    return nullptr;
  }
}
void* operator new[](size_t n, const std::nothrow_t& tag) noexcept { return operator new(n, tag); }
void operator delete(void* p) noexcept { uncounted(p); }
void operator delete[](void* p) noexcept { uncounted(p); }
void operator delete(void* p, size_t) noexcept { uncounted(p); }
void operator delete[](void* p, size_t) noexcept { uncounted(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { uncounted(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { uncounted(p); }

using namespace meshsweeper;

// The promise: two triangulations of one square at a tolerance of 1e-9 (the case that needs a
// limit) under limits from 1 MB to 64 MB, on 1 and 2 threads; the most memory held at once
// during the whole call, everything the library allocated included (its hierarchies, streams
// and scratch), stays within the limit. Checking the tables as they are, without predicting the
// next round's growth, ends 10-30% above it. (A review found the first prediction short of the
// tables' peak in some rounds, by 1%: push_back's growth taken for resize's, a sample per chunk
// and three scratch tables left out; the counting here did not see that, the fix made the
// prediction an upper bound by construction.)
TEST_CASE("max_bytes bounds the memory a Hausdorff computation holds at once") {
  Mesh a, b;
  a.positions = b.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
  a.triangles = {{0, 1, 2}, {0, 2, 3}};
  b.triangles = {{1, 2, 3}, {1, 3, 0}};
  for (const unsigned threads : {1u, 2u}) {
    for (const uint64_t limit : {uint64_t{1} << 20, uint64_t{5} << 20, uint64_t{19} << 20, uint64_t{64} << 20}) {
      HausdorffOptions options;
      options.tolerance = 1e-9;
      options.threads = threads;
      options.max_bytes = limit;
      const int64_t before = g_live.load();
      g_peak = before;
      const HausdorffResult r = hausdorff(a, b, options);
      const int64_t held = g_peak.load() - before;
      INFO("threads " << threads << ", limit " << limit << ": held " << held << ", tables " << r.table_bytes);
      CHECK(r.memory_limited);
      CHECK(r.table_bytes <= limit);
      CHECK(held <= static_cast<int64_t>(limit));
      CHECK(held > static_cast<int64_t>(limit / 4));  // the counting sees the tables
      CHECK(r.lower <= 1e-15);                        // a certified interval about the true 0
      CHECK(r.upper >= r.lower);
    }
  }
}

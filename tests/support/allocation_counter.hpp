// Counts the allocations of a test binary while `g_counting` is set: the
// per-sample paths (the emission thread, a fault timeline's step()) must
// allocate nothing. It replaces the global operator new and delete, so
// include it in exactly one translation unit of a test binary.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace {
std::atomic<bool> g_counting{false};
std::atomic<std::uint64_t> g_allocations{0};
}  // namespace

void* operator new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
// GCC sees free() on what `new` returned; here `new` is malloc.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#include "tests/support/replaced_new_forms.hpp"  // the nothrow and array forms through these two
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

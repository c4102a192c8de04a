// The other forms of the global operator new and delete, for a test file that
// replaces `operator new(std::size_t)` and `operator delete(void*)` to count
// allocations (tests/support/allocation_counter.hpp, the link-fault and the
// device tests): each form here goes through those two, so every allocation
// is counted and every block is freed by the function that matches its
// allocation. Without them, under AddressSanitizer the nothrow and array
// forms stay ASan's own: std::stable_sort's nothrow buffer then came from
// ASan and went back through the replaced delete to free(), an
// alloc-dealloc-mismatch that aborted an unrelated test once the tests of a
// room shared one binary (issue 25). Include it once, in the file that
// replaces the two, after them.
#pragma once

#include <cstddef>
#include <new>

void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return ::operator new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n) { return ::operator new(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return ::operator new(n);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p, const std::nothrow_t&) noexcept { ::operator delete(p); }
void operator delete[](void* p) noexcept { ::operator delete(p); }
void operator delete[](void* p, std::size_t) noexcept { ::operator delete(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { ::operator delete(p); }

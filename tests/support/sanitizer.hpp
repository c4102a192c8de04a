#pragma once
// IMUEMU_UNDER_ASAN: 1 when this file is compiled with AddressSanitizer. GCC
// defines __SANITIZE_ADDRESS__; clang (the ASan flavour's compiler,
// scripts/build.sh) does not and answers __has_feature(address_sanitizer).
// Tests use it to shorten long runs and to skip peak-RSS limits, which under
// ASan would measure its shadow memory.
#if defined(__SANITIZE_ADDRESS__)
#define IMUEMU_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define IMUEMU_UNDER_ASAN 1
#endif
#endif
#ifndef IMUEMU_UNDER_ASAN
#define IMUEMU_UNDER_ASAN 0
#endif

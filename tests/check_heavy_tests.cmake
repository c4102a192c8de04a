# cmake -DBUILD_DIR=... -P check_heavy_tests.cmake: every name in
# heavy_tests.cmake is a test ctest knows (ctest silently skips unknown names).
set(IMUEMU_HEAVY_LIST_ONLY ON)
include(${CMAKE_CURRENT_LIST_DIR}/heavy_tests.cmake)
execute_process(COMMAND ${CMAKE_CTEST_COMMAND} --test-dir ${BUILD_DIR} -N -L heavy
                OUTPUT_VARIABLE listed RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "ctest -N -L heavy failed (${rc})")
endif()
foreach(name IN LISTS IMUEMU_HEAVY_TESTS)
  string(FIND "${listed}" ": ${name}\n" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "tests/heavy_tests.cmake names ${name}, which no test binary defines")
  endif()
endforeach()
list(LENGTH IMUEMU_HEAVY_TESTS count)
message(STATUS "all ${count} heavy tests exist")

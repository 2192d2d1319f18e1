# SPDX-License-Identifier: GPL-3.0-or-later
# The instruction-set extensions `-march=native` enables on the build machine, as the names GCC's
# __builtin_cpu_supports knows, in SPHLES_NATIVE_CPU_FEATURES (a space-separated string): what a
# native build's sphles checks the running processor for before anything else runs
# (app/cpu_check.cpp), so that a binary moved to an older machine stops with a message naming
# what is missing instead of dying of an illegal instruction. Only the extensions the compiler
# may use for sphles' code are listed (vector, FMA and bit-manipulation sets).
function(sphles_native_cpu_features out)
  execute_process(
    COMMAND ${CMAKE_CXX_COMPILER} -march=native -dM -E -x c++ /dev/null
    OUTPUT_VARIABLE macros
    RESULT_VARIABLE status
    ERROR_QUIET)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "cannot list the compiler's -march=native macros (${CMAKE_CXX_COMPILER})")
  endif()
  set(known SSE4_2 POPCNT AVX F16C AVX2 FMA BMI BMI2 AVX512F AVX512CD AVX512BW AVX512DQ AVX512VL
    AVX512IFMA AVX512VBMI AVX512VBMI2 AVX512VNNI AVX512BITALG AVX512VPOPCNTDQ)
  set(features "")
  foreach(name IN LISTS known)
    if(macros MATCHES "#define __${name}__ 1")
      string(TOLOWER "${name}" feature)
      string(REPLACE "sse4_2" "sse4.2" feature "${feature}")
      string(APPEND features " ${feature}")
    endif()
  endforeach()
  string(STRIP "${features}" features)
  set(${out} "${features}" PARENT_SCOPE)
endfunction()

# Compiler flags that decide results bit for bit, and the instruction set.
#
# Floating point: no fast-math, and no implicit contraction of a*b+c into an
# FMA (-ffp-contract=off). Kernels that want an FMA ask for it explicitly
# (lane::fmadd), so the scalar reference lane and the SIMD lanes round the
# same way and results do not depend on the compiler's contraction choices.
add_library(lockstep_flags INTERFACE)
target_compile_options(lockstep_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wno-unused-parameter)

set(LOCKSTEP_PUBLIC_FLAGS -ffp-contract=off -fno-fast-math)
if(LOCKSTEP_PORTABLE)
  set(LOCKSTEP_ARCH_FLAGS -march=x86-64 -mtune=generic)
else()
  set(LOCKSTEP_ARCH_FLAGS -march=native)
endif()
list(APPEND LOCKSTEP_PUBLIC_FLAGS ${LOCKSTEP_ARCH_FLAGS})

# The instruction-set extensions the chosen flags enable, so that the CPU
# check (compiled for baseline x86-64) can test for each before anything
# else runs.
execute_process(
  COMMAND ${CMAKE_CXX_COMPILER} ${LOCKSTEP_ARCH_FLAGS} -dM -E -x c++ /dev/null
  OUTPUT_VARIABLE _lockstep_predefined
  RESULT_VARIABLE _lockstep_predefined_rc)
set(LOCKSTEP_REQUIRED_ISA "")
foreach(_isa SSE4_2 AVX AVX2 FMA BMI2 AVX512F AVX512BW AVX512DQ AVX512VL AVX512CD)
  if(_lockstep_predefined MATCHES "#define __${_isa}__ 1")
    list(APPEND LOCKSTEP_REQUIRED_ISA ${_isa})
  endif()
endforeach()
message(STATUS "lockstep: instruction set extensions required: ${LOCKSTEP_REQUIRED_ISA}")

# Compiler flags that decide results bit for bit, and the instruction set.
#
# Floating point: no fast-math, and no implicit contraction of a*b+c into an
# FMA (-ffp-contract=off). Kernels that want an FMA ask for it explicitly
# (lane::fmadd), so the scalar reference lane and the SIMD lanes round the
# same way and results do not depend on the compiler's contraction choices.
add_library(lockstep_flags INTERFACE)

# Debian's xsimd 8.1 target lists "xtl" as a link dependency (the package was
# built with its optional xtl support), which becomes a failing -lxtl when
# libxtl-dev is absent. lockstep uses nothing of xtl: an empty stand-in
# target satisfies the reference. (lockstepConfig.cmake does the same.)
if(TARGET xsimd AND NOT TARGET xtl)
  find_package(xtl QUIET)
  if(NOT TARGET xtl)
    add_library(xtl INTERFACE IMPORTED)
  endif()
endif()
target_compile_options(lockstep_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wno-unused-parameter)

set(LOCKSTEP_PUBLIC_FLAGS -ffp-contract=off -fno-fast-math)
# g++ 12's basic-block (SLP) vectoriser still fuses some a*b+c of the scalar
# reference lane into FMAs despite -ffp-contract=off (seen in integrate():
# scalar and SIMD lanes then differ in the last bit); without it g++ builds
# keep the lanes bit-identical. clang needs no such flag.
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  list(APPEND LOCKSTEP_PUBLIC_FLAGS -fno-tree-slp-vectorize)
endif()
# The instruction set: LOCKSTEP_MARCH (native by default), or baseline
# x86-64 with LOCKSTEP_PORTABLE. Results depend on it in one way only: a
# target with FMA (x86-64-v3 and newer, native on any AVX2 or AVX-512 CPU)
# fuses lane::fmadd, one without (x86-64) rounds a*b+c twice. The SIMD width
# does not change a copy's bits: each lane computes the scalar reference.
if(LOCKSTEP_PORTABLE)
  set(LOCKSTEP_MARCH_USED x86-64)
else()
  set(LOCKSTEP_MARCH_USED ${LOCKSTEP_MARCH})
endif()
if(LOCKSTEP_MARCH_USED STREQUAL "x86-64")
  set(LOCKSTEP_ARCH_FLAGS -march=x86-64 -mtune=generic)
else()
  # With AVX-512, compilers default to 256-bit vectors for the code they
  # generate themselves (struct copies, zero fills, memcpy): a 64-byte lane
  # then reloaded from two 32-byte stores misses store-to-load forwarding,
  # a stall of about 15 cycles each, all through the kernels. Whole-width
  # vectors keep their copies the width of the lanes.
  set(LOCKSTEP_ARCH_FLAGS -march=${LOCKSTEP_MARCH_USED} -mprefer-vector-width=512)
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
# Each name is the compiler's predefined macro without underscores; the CPU
# check maps it to the __builtin_cpu_supports feature name.
foreach(_isa SSSE3 SSE4_1 SSE4_2 POPCNT AVX AVX2 FMA BMI BMI2
             AVX512F AVX512BW AVX512DQ AVX512VL AVX512CD AVX512IFMA AVX512VBMI
             AVX512VBMI2 AVX512VNNI AVX512BITALG AVX512VPOPCNTDQ AVX512BF16
             GFNI VPCLMULQDQ)
  if(_lockstep_predefined MATCHES "#define __${_isa}__ 1")
    list(APPEND LOCKSTEP_REQUIRED_ISA ${_isa})
  endif()
endforeach()
message(STATUS "lockstep: instruction set extensions required: ${LOCKSTEP_REQUIRED_ISA}")

# The CPU check: an object library compiled for baseline x86-64 (whatever the
# flags above say), linked into every executable. Its constructor runs before
# any code built with LOCKSTEP_ARCH_FLAGS and exits with code 3, naming the
# missing extensions, instead of letting the program die of SIGILL.
string(REPLACE ";" "," _lockstep_isa_csv "${LOCKSTEP_REQUIRED_ISA}")
# The flags as one string for the message (a CMake list would split the definition).
string(JOIN " " _lockstep_arch_text ${LOCKSTEP_ARCH_FLAGS})
add_library(lockstep_cpu_check OBJECT ${PROJECT_SOURCE_DIR}/tools/cpu_check.cpp)
target_compile_options(lockstep_cpu_check PRIVATE -march=x86-64 -mtune=generic)
target_compile_definitions(lockstep_cpu_check PRIVATE
  LOCKSTEP_REQUIRED_ISA="${_lockstep_isa_csv}"
  LOCKSTEP_ARCH_FLAGS="${_lockstep_arch_text}")
target_link_libraries(lockstep_cpu_check PRIVATE lockstep_flags)
target_include_directories(lockstep_cpu_check PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>)
add_library(lockstep::lockstep_cpu_check ALIAS lockstep_cpu_check)

# Where tests and benchmarks find models: the shared real-robot URDFs beside
# the project, and the project's own bundled models.
get_filename_component(LOCKSTEP_SHARED_MODELS_DIR "${PROJECT_SOURCE_DIR}/../shared/models" ABSOLUTE)
add_library(lockstep_model_dirs INTERFACE)
target_compile_definitions(lockstep_model_dirs INTERFACE
  LOCKSTEP_SHARED_MODELS_DIR="${LOCKSTEP_SHARED_MODELS_DIR}"
  LOCKSTEP_MODELS_DIR="${PROJECT_SOURCE_DIR}/models")

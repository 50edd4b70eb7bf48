# The Teensy 3.5 image inside the Python package (included by the top-level CMakeLists.txt when
# the package is built: pip install ., scikit-build-core).
#
# When the ARM toolchain is there, the image is built by a second CMake build of this source
# tree with the `teensy35` configure preset (CMakePresets.json: the toolchain file, Release,
# -O2 -DNDEBUG), so it is the preset's image byte for byte, and heliquad-fw-teensy35.elf and
# .hex are installed into the package at heliquad/firmware/teensy35/, where
# heliquad.sim.base.firmware_image.teensy35_image() finds them (docs/teensy35.md).
#
#   HQ_TEENSY_IMAGE=AUTO (default)  build it when the toolchain is complete, else say why once
#                   ON              the image is required: no toolchain is a configure error (CI)
#                   OFF             never build it
#
# pip install . -Ccmake.define.HQ_TEENSY_IMAGE=ON (or OFF). HQ_DMP_IMAGE, when given, is
# compiled into the image as into the host build.
set(HQ_TEENSY_IMAGE AUTO CACHE STRING
    "build the Teensy 3.5 image into the package: AUTO (when arm-none-eabi-g++ is there), ON, OFF")
set_property(CACHE HQ_TEENSY_IMAGE PROPERTY STRINGS AUTO ON OFF)
string(TOUPPER "${HQ_TEENSY_IMAGE}" hq_teensy_mode)
if(NOT hq_teensy_mode MATCHES "^(AUTO|ON|OFF)$")
  message(FATAL_ERROR "HQ_TEENSY_IMAGE is '${HQ_TEENSY_IMAGE}': use AUTO, ON or OFF")
endif()

set(HQ_TEENSY_PACKAGES "gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-dev")

# Why the image cannot be built here, or "" when it can: the compiler, newlib-nano and the C++
# headers (each is its own Debian package) are all needed; a partial toolchain is reported as
# such instead of failing the install halfway through the image's build.
function(hq_teensy_toolchain_problem out)
  set(${out} "" PARENT_SCOPE)
  if(CMAKE_VERSION VERSION_LESS 3.21)
    set(${out} "the teensy35 preset needs CMake 3.21 or newer (this is ${CMAKE_VERSION})" PARENT_SCOPE)
    return()
  endif()
  find_program(HQ_ARM_CXX NAMES arm-none-eabi-g++)
  if(NOT HQ_ARM_CXX)
    set(${out} "arm-none-eabi-g++ not found" PARENT_SCOPE)
    return()
  endif()
  set(arm_flags -mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard)
  execute_process(COMMAND "${HQ_ARM_CXX}" ${arm_flags} -print-file-name=libc_nano.a
                  OUTPUT_VARIABLE libc OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0 OR NOT IS_ABSOLUTE "${libc}")
    set(${out} "${HQ_ARM_CXX} has no newlib-nano (libc_nano.a)" PARENT_SCOPE)
    return()
  endif()
  set(probe "${CMAKE_CURRENT_BINARY_DIR}/hq_teensy_probe.cpp")
  file(WRITE "${probe}" "#include <array>\n#include <cstdint>\n#include <cmath>\n")
  execute_process(COMMAND "${HQ_ARM_CXX}" ${arm_flags} -std=c++17 -fsyntax-only "${probe}"
                  RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
  if(NOT rc EQUAL 0)
    set(${out} "${HQ_ARM_CXX} has no C++ standard headers (<array>, <cstdint>, <cmath>)" PARENT_SCOPE)
  endif()
endfunction()

if(hq_teensy_mode STREQUAL "OFF")
  message(STATUS "heliquad: the Teensy 3.5 image is not built (HQ_TEENSY_IMAGE=OFF)")
  return()
endif()
hq_teensy_toolchain_problem(hq_teensy_problem)
if(hq_teensy_problem)
  set(hq_teensy_fix "apt-get install ${HQ_TEENSY_PACKAGES}, then reinstall heliquad")
  if(hq_teensy_mode STREQUAL "ON")
    message(FATAL_ERROR "HQ_TEENSY_IMAGE=ON but ${hq_teensy_problem}: ${hq_teensy_fix}")
  endif()
  message(STATUS "heliquad: the Teensy 3.5 image is not built (${hq_teensy_problem}): ${hq_teensy_fix}")
  return()
endif()

include(ExternalProject)
set(hq_teensy_bin "${CMAKE_BINARY_DIR}/teensy35")
# A build folder reused for another checkout (pip's -Cbuild-dir, a moved clone) holds an inner
# cache made for the other source tree, which CMake refuses to reconfigure: start it afresh.
if(EXISTS "${hq_teensy_bin}/CMakeCache.txt")
  file(STRINGS "${hq_teensy_bin}/CMakeCache.txt" hq_teensy_home REGEX "^CMAKE_HOME_DIRECTORY:")
  string(REGEX REPLACE "^[^=]*=" "" hq_teensy_home "${hq_teensy_home}")
  if(NOT hq_teensy_home STREQUAL CMAKE_SOURCE_DIR)
    message(STATUS "heliquad: ${hq_teensy_bin} was configured for ${hq_teensy_home}: removed")
    file(REMOVE_RECURSE "${hq_teensy_bin}" "${CMAKE_BINARY_DIR}/hq_teensy35_image-prefix")
  endif()
endif()
set(hq_teensy_generator -G "${CMAKE_GENERATOR}")
if(CMAKE_MAKE_PROGRAM)
  list(APPEND hq_teensy_generator "-DCMAKE_MAKE_PROGRAM=${CMAKE_MAKE_PROGRAM}")
endif()
# The preset runs mavgen with the Python that CMake finds: this build's (it has pymavlink).
ExternalProject_Add(hq_teensy35_image
  SOURCE_DIR "${CMAKE_SOURCE_DIR}"
  BINARY_DIR "${hq_teensy_bin}"
  CONFIGURE_COMMAND "${CMAKE_COMMAND}" -S "${CMAKE_SOURCE_DIR}" -B "${hq_teensy_bin}"
                    --preset teensy35 ${hq_teensy_generator}
                    "-DPython3_EXECUTABLE=${Python3_EXECUTABLE}"
                    "-DHQ_DMP_IMAGE=${HQ_DMP_IMAGE}"
  # Always run the (incremental) build: a firmware source that changed is rebuilt, and an
  # unchanged tree costs one up-to-date check.
  BUILD_COMMAND "${CMAKE_COMMAND}" --build "${hq_teensy_bin}" --parallel 2
  BUILD_ALWAYS TRUE
  BUILD_BYPRODUCTS "${hq_teensy_bin}/heliquad-fw-teensy35.elf" "${hq_teensy_bin}/heliquad-fw-teensy35.hex"
  INSTALL_COMMAND ""
  TEST_COMMAND "")
install(FILES "${hq_teensy_bin}/heliquad-fw-teensy35.elf" "${hq_teensy_bin}/heliquad-fw-teensy35.hex"
        DESTINATION heliquad/firmware/teensy35)
message(STATUS "heliquad: building the Teensy 3.5 image with ${HQ_ARM_CXX} (preset teensy35) into the package")

# Helpers shared by every library, service and test (STYLE.md §10).

# -Wno-maybe-uninitialized: g++ 12 reports false positives inside Eigen fixed-size temporaries.
function(cell_warning_options target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion -Wno-missing-field-initializers
      -Wno-maybe-uninitialized>)
  if(CELL_WERROR)
    target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
  endif()
endfunction()

# The unit tests' own code: -O1 in an optimised build; it sets up and checks, the libraries it
# tests do the work (and keep the build type's -O2). Half the build is test code; -O1 cuts its
# compile by a fifth. In the sanitizer build (CELL_SANITIZE: libraries and services at -Og) the
# test code is compiled at -O0: ASan and UBSan instrument it all the same, nothing of it is
# optimised away from them, and the instrumented compile of a test batch takes 35 s instead of
# 60 (gateway_test, measured), which is a fifth of the sanitizer build. Except where the test's
# own code computes (cell_add_test COMPUTES: scenarios generated, round trips, fuzzing): there
# -O0 made the tests themselves slower than it made the compile faster (calibration, kinematics
# and rapt, sanitized: their 202 tests 156 s at -O0 and 57 s at -O1, for about 20 s more
# compile), so they keep -O1, without the precompiled header (g++ refuses one made at -O0).
if(CELL_SANITIZE)
  set(CELL_TEST_CODE_OPT -O0)
else()
  set(CELL_TEST_CODE_OPT $<$<CONFIG:RelWithDebInfo,Release>:-O1>)
endif()

# Precompiled headers (CELL_PCH). Half of a test batch's compile time was parsing the same
# standard, Eigen, fmt, JSON and gtest headers again (gateway_test: 39 s, 12 s of it parsing and
# 12 s of it the kernel mapping the parser's memory; 21 s with the header below precompiled).
# Two headers are compiled once each and reused by every target (REUSE_FROM): one for the
# libraries, services, clients and benchmarks, one with gtest and gmock for the unit tests
# (gtest's GTEST_HAS_PTHREAD is defined only where gtest is linked, and g++ refuses a header
# precompiled with a macro the user lacks). A target whose options make g++ refuse the shared
# header fails the build (-Winvalid-pch with -Werror) instead of silently parsing it all again.
# scripts/tidy.sh configures its own tree without them: clang cannot read g++'s .gch files.
set(CELL_PCH_HEADERS
    <algorithm> <array> <atomic> <chrono> <cmath> <cstdint> <cstdio> <cstdlib> <cstring>
    <filesystem> <fstream> <functional> <map> <memory> <mutex> <numbers> <optional> <random>
    <set> <sstream> <string> <string_view> <thread> <vector>
    <Eigen/Geometry> <fmt/format.h> <nlohmann/json.hpp>)
if(CELL_PCH)
  # What the headers need, given to every target that uses them: the same include paths and
  # the same definitions (fmt's FMT_SHARED) as where they were compiled.
  add_library(cell_pch_deps INTERFACE)
  target_link_libraries(cell_pch_deps INTERFACE Eigen3::Eigen fmt::fmt
                        nlohmann_json::nlohmann_json)
  add_library(cell_pch_lib STATIC ${PROJECT_SOURCE_DIR}/cmake/pch_anchor.cpp)
  target_link_libraries(cell_pch_lib PRIVATE cell_pch_deps)
  target_compile_features(cell_pch_lib PRIVATE cxx_std_20)
  cell_warning_options(cell_pch_lib)
  target_precompile_headers(cell_pch_lib PRIVATE ${CELL_PCH_HEADERS})
  if(BUILD_TESTING)
    add_library(cell_pch_test STATIC ${PROJECT_SOURCE_DIR}/cmake/pch_anchor.cpp)
    target_link_libraries(cell_pch_test PRIVATE cell_pch_deps GTest::gmock)
    target_compile_features(cell_pch_test PRIVATE cxx_std_20)
    cell_warning_options(cell_pch_test)
    # Compiled as the tests' own code is (CELL_TEST_CODE_OPT, cell_add_test).
    target_compile_options(cell_pch_test PRIVATE ${CELL_TEST_CODE_OPT})
    target_precompile_headers(cell_pch_test PRIVATE ${CELL_PCH_HEADERS} <gtest/gtest.h>
                              <gmock/gmock.h>)
  endif()
endif()

# cell_set_warnings(<target> [TEST] [NO_PCH]): the project's warnings and its precompiled header
# (the unit tests' with TEST; none with NO_PCH). Every C++ target of the project calls it.
function(cell_set_warnings target)
  cmake_parse_arguments(ARG "TEST;NO_PCH" "" "" ${ARGN})
  cell_warning_options(${target})
  if(CELL_PCH AND NOT ARG_NO_PCH)
    target_link_libraries(${target} PRIVATE cell_pch_deps)
    if(ARG_TEST)
      target_precompile_headers(${target} REUSE_FROM cell_pch_test)
    else()
      target_precompile_headers(${target} REUSE_FROM cell_pch_lib)
    endif()
  endif()
endfunction()

# cell_add_library(<name> SOURCES ... DEPENDS ... [PRIVATE_DEPENDS ...]) -> cell_<name>, cell::<name>
function(cell_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPENDS;PRIVATE_DEPENDS" ${ARGN})
  if(ARG_SOURCES)
    add_library(cell_${name} STATIC ${ARG_SOURCES})
    target_include_directories(cell_${name}
      PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include
      PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
    target_link_libraries(cell_${name} PUBLIC ${ARG_DEPENDS} PRIVATE ${ARG_PRIVATE_DEPENDS})
    target_compile_features(cell_${name} PUBLIC cxx_std_20)
    cell_set_warnings(cell_${name})
  else()
    add_library(cell_${name} INTERFACE)
    target_include_directories(cell_${name} INTERFACE ${CMAKE_CURRENT_SOURCE_DIR}/include)
    target_link_libraries(cell_${name} INTERFACE ${ARG_DEPENDS})
    target_compile_features(cell_${name} INTERFACE cxx_std_20)
  endif()
  add_library(cell::${name} ALIAS cell_${name})
endfunction()

# cell_add_test(<name> SOURCES ... DEPENDS ... [LABELS ...] [TIMEOUT s] [SERIAL]
#               [PROCESSORS n] [COST s] [RESOURCE_LOCK lock] [COMPUTES])
# One executable per library; every TEST becomes a ctest entry "<name>.<Suite>.<Test>".
# COMPUTES: the test code itself computes; it keeps -O1 in the sanitizer build
# (CELL_TEST_CODE_OPT above).
#
# How ctest schedules them (scripts/test.sh runs `ctest -j <4 x cores>`: a slot is a quarter of
# a core, so that tests which mostly wait on real time run several at once):
#   SERIAL         nothing else runs beside it: it times a robot or a browser against real time
#                  and must have the machine (a 1 kHz servo, a belt at 2 m/s).
#   PROCESSORS n   the slots it holds while it runs: 4 x the cores it keeps busy, measured alone
#                  (at least 1, the default). Unit tests that compute for seconds hold 4.
#   COST s         about how long it runs: ctest starts the costliest first, so the long
#                  multi-process tests are under way before the short ones fill the gaps.
#   RESOURCE_LOCK  tests that hold the same lock never overlap (the network lab's namespaces).
function(cell_add_test name)
  cmake_parse_arguments(ARG "SERIAL;COMPUTES" "TIMEOUT;PROCESSORS;COST"
                        "SOURCES;DEPENDS;LABELS;RESOURCE_LOCK" ${ARGN})
  add_executable(${name}_test ${ARG_SOURCES})
  target_link_libraries(${name}_test PRIVATE ${ARG_DEPENDS} GTest::gmock_main)
  if(ARG_COMPUTES AND CELL_SANITIZE)
    cell_set_warnings(${name}_test TEST NO_PCH)
    target_compile_options(${name}_test PRIVATE -O1)
  else()
    cell_set_warnings(${name}_test TEST)
    target_compile_options(${name}_test PRIVATE ${CELL_TEST_CODE_OPT})
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 120)
  endif()
  # gtest_discover_tests flattens PROPERTIES, which splits a list-valued ENVIRONMENT into
  # separate words: repeat the ENVIRONMENT keyword before each entry so every one survives.
  set(env "CELL_SOURCE_DIR=${CMAKE_SOURCE_DIR};CELL_BIN_DIR=${CELL_BIN_DIR};CYCLONEDDS_URI=file://${CMAKE_SOURCE_DIR}/config/dds/loopback.xml")
  string(REPLACE ";" ";ENVIRONMENT;" env "${env}")
  set(props TIMEOUT ${ARG_TIMEOUT} ENVIRONMENT ${env})
  if(ARG_LABELS)
    # The same flattening splits a label list: repeat the keyword before each label too.
    string(REPLACE ";" ";LABELS;" labels "${ARG_LABELS}")
    list(APPEND props LABELS ${labels})
  endif()
  if(ARG_SERIAL)
    list(APPEND props RUN_SERIAL TRUE)
  endif()
  if(ARG_PROCESSORS)
    list(APPEND props PROCESSORS ${ARG_PROCESSORS})
  endif()
  if(ARG_COST)
    list(APPEND props COST ${ARG_COST})
  endif()
  if(ARG_RESOURCE_LOCK)
    list(APPEND props RESOURCE_LOCK ${ARG_RESOURCE_LOCK})
  endif()
  gtest_discover_tests(${name}_test TEST_PREFIX "${name}." DISCOVERY_TIMEOUT 60
                       PROPERTIES ${props})
endfunction()

# cell_test_properties(<name> <Suite.Test> <PROPERTY value>...): ctest properties of one test
# of <name>_test, where the test differs from the rest of its executable (a test that waits on a
# robot holds fewer slots than its neighbour that computes). gtest_discover_tests names the tests
# only when the executable is built, so the properties go into a file ctest includes after the
# discovered tests; a test that no longer exists is an error there ("Can not find test").
function(cell_test_properties name test)
  set(file "${CMAKE_CURRENT_BINARY_DIR}/${name}_test_properties.cmake")
  get_property(started DIRECTORY PROPERTY CELL_TEST_PROPERTY_FILES)
  if(NOT file IN_LIST started)
    file(WRITE "${file}" "# Generated by cell_test_properties (cmake/CellTargets.cmake).\n")
    set_property(DIRECTORY APPEND PROPERTY CELL_TEST_PROPERTY_FILES "${file}")
    set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES "${file}")
  endif()
  list(JOIN ARGN " " props)
  file(APPEND "${file}" "set_tests_properties(\"${name}.${test}\" PROPERTIES ${props})\n")
endfunction()

# cell_add_service(<svc> SOURCES <lib sources> DEPENDS ...) -> cell_<svc>_lib + executable cell-<svc>
function(cell_add_service svc)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPENDS" ${ARGN})
  add_library(cell_${svc}_lib STATIC ${ARG_SOURCES})
  target_include_directories(cell_${svc}_lib PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_link_libraries(cell_${svc}_lib PUBLIC ${ARG_DEPENDS} cell::service)
  cell_set_warnings(cell_${svc}_lib)
  add_executable(cell-${svc} src/main.cpp)
  target_link_libraries(cell-${svc} PRIVATE cell_${svc}_lib)
  cell_set_warnings(cell-${svc})
endfunction()

# cell_add_memcheck(<name>): runs <name>_test whole under valgrind memcheck as one ctest entry
# "<name>.memcheck" (label memcheck); fails on any memory error or definite/indirect leak.
find_program(CELL_VALGRIND valgrind)
function(cell_add_memcheck name)
  if(CELL_SANITIZE)
    return()  # valgrind cannot run an AddressSanitizer binary; the sanitizers check it instead
  endif()
  if(NOT CELL_VALGRIND)
    message(WARNING "valgrind not found: ${name}.memcheck not registered")
    return()
  endif()
  add_test(NAME ${name}.memcheck
           COMMAND ${CELL_VALGRIND} --leak-check=full --errors-for-leak-kinds=definite,indirect
                   --error-exitcode=9 -q $<TARGET_FILE:${name}_test>)
  set_tests_properties(${name}.memcheck PROPERTIES LABELS memcheck TIMEOUT 300 ENVIRONMENT
      "CELL_SOURCE_DIR=${CMAKE_SOURCE_DIR};CELL_BIN_DIR=${CELL_BIN_DIR};CYCLONEDDS_URI=file://${CMAKE_SOURCE_DIR}/config/dds/loopback.xml")
endfunction()

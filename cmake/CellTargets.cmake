# Helpers shared by every library, service and test (STYLE.md §10).

# -Wno-maybe-uninitialized: g++ 12 reports false positives inside Eigen fixed-size temporaries.
function(cell_set_warnings target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion -Wno-missing-field-initializers
      -Wno-maybe-uninitialized>)
  if(CELL_WERROR)
    target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
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

# cell_add_test(<name> SOURCES ... DEPENDS ... [LABELS ...] [TIMEOUT s])
# One executable per library; every TEST becomes a ctest entry "<name>.<Suite>.<Test>".
function(cell_add_test name)
  cmake_parse_arguments(ARG "SERIAL" "TIMEOUT" "SOURCES;DEPENDS;LABELS" ${ARGN})
  add_executable(${name}_test ${ARG_SOURCES})
  target_link_libraries(${name}_test PRIVATE ${ARG_DEPENDS} GTest::gmock_main)
  cell_set_warnings(${name}_test)
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
  if(ARG_SERIAL)  # timing-sensitive (a 1 kHz hard deadline): nothing else runs beside it
    list(APPEND props RUN_SERIAL TRUE)
  endif()
  gtest_discover_tests(${name}_test TEST_PREFIX "${name}." DISCOVERY_TIMEOUT 60
                       PROPERTIES ${props})
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

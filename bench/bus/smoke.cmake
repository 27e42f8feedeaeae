# ctest smoke run of bus_bench (bench/bus/CMakeLists.txt): a short run on its own domain.
# Prints BUS_BENCH_SMOKE_FAILED when bus_bench exits non-zero or hangs.
execute_process(COMMAND ${BUS_BENCH} --quick --domain auto
                RESULT_VARIABLE rc
                TIMEOUT 50)
if(NOT rc STREQUAL "0")
  message("BUS_BENCH_SMOKE_FAILED: bus_bench --quick ended with '${rc}'")
  message(FATAL_ERROR "bus_bench smoke run failed")
endif()

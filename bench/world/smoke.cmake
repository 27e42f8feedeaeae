# ctest smoke run of world_bench (bench/world/CMakeLists.txt). Prints WORLD_BENCH_SMOKE_FAILED
# when world_bench exits non-zero or hangs.
execute_process(COMMAND ${WORLD_BENCH} --quick
                RESULT_VARIABLE rc
                TIMEOUT 110)
if(NOT rc STREQUAL "0")
  message("WORLD_BENCH_SMOKE_FAILED: world_bench --quick ended with '${rc}'")
  message(FATAL_ERROR "world_bench smoke run failed")
endif()

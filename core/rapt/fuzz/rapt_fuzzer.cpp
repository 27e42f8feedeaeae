// libFuzzer entry point for the RAPT compiler and run time (CELL_RAPT_FUZZER=ON, clang only):
// any byte string must compile or fail with positioned diagnostics, never crash; a program that
// compiles is also run (with no readings: every fixable package must then be refused cleanly).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "cell/rapt/compiler.hpp"
#include "cell/rapt/runtime.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view source(reinterpret_cast<const char*>(data), size);
  cell::rapt::Diagnostics diags("fuzz.rapt");
  auto program = cell::rapt::compile(source, "fuzz.rapt", diags);
  for (const cell::rapt::Diagnostic& d : diags.items()) {
    if (!d.loc.known()) {
      __builtin_trap();  // every diagnostic must have a position
    }
  }
  if (program) {
    (void)cell::rapt::run(*program, {});
  }
  return 0;
}

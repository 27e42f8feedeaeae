#pragma once

// The shipped dialect file (config/excalibur_dialect.yaml: CELL_EXCALIBUR_DIALECT) in tests.

#include <gmock/gmock.h>

#include "cell/protocols/excalibur/dialect.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::protocols::excalibur::test {

/// The shipped dialect; a test failure if it does not load.
inline Dialect shipped() {
  auto d = Dialect::load(CELL_EXCALIBUR_DIALECT);
  EXPECT_THAT(d, ::cell::testing::IsOk());
  return *d;
}

}  // namespace cell::protocols::excalibur::test

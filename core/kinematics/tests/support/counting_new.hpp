#pragma once

// A counting replacement of the global operator new, for the allocation tests. The replacement
// lives in its own translation unit (counting_new.cpp) so that the compiler never inlines
// operator new/delete into the code under test; it is linked into kinematics_test only.

namespace cell::kinematics::test {

/// Number of calls of the global operator new (all forms) since the program started.
long allocation_count() noexcept;

}  // namespace cell::kinematics::test

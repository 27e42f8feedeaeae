#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "cell/rapt/compiler.hpp"
#include "cell/rapt/runtime.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

std::string read(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// One random edit of RAPT source: delete, insert, duplicate or swap lines, replace a word by a
/// keyword or a number, change a digit. Deterministic for a given generator state.
std::string mutate(std::string text, std::mt19937& rng) {
  static const char* kWords[] = {"move",    "turn",   "against", "fits",      "tied",     "untied",
                                 "combine", "tercom", "look",    "inviolate", "body",     "terbod",
                                 "world",   "of",     "perpto",  "about",     "face",     "edge",
                                 "camera",  "terapt", "remark",  "-1e9",      "0",        "1e308",
                                 ";",       "/",      ",",       "=",         "\n",       "subass",
                                 "tersub",  "issub",  "agent",   "setcamera", "tolerance"};
  std::uniform_int_distribution<int> op(0, 6);
  auto pos = [&](std::size_t n) {
    return n == 0 ? std::size_t{0} : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
  };
  const int edits = 1 + static_cast<int>(pos(4));
  for (int e = 0; e < edits && !text.empty(); ++e) {
    switch (op(rng)) {
      case 0: {  // delete a short range
        const std::size_t at = pos(text.size());
        text.erase(at, 1 + pos(6));
        break;
      }
      case 1: {  // insert a random byte (printable or not)
        text.insert(pos(text.size() + 1), 1,
                    static_cast<char>(std::uniform_int_distribution<int>(1, 255)(rng)));
        break;
      }
      case 2: {  // insert a word
        text.insert(pos(text.size() + 1), kWords[pos(sizeof(kWords) / sizeof(kWords[0]))]);
        break;
      }
      case 3: {  // duplicate a line
        const std::size_t at = text.rfind('\n', pos(text.size()));
        const std::size_t start = at == std::string::npos ? 0 : at + 1;
        const std::size_t end = text.find('\n', start);
        const std::string line =
            text.substr(start, end == std::string::npos ? end : end - start + 1);
        text.insert(pos(text.size() + 1), line);
        break;
      }
      case 4: {  // replace a word by another word
        const std::size_t at = pos(text.size());
        std::size_t end = at;
        while (end < text.size() && std::isalnum(static_cast<unsigned char>(text[end])) != 0) {
          ++end;
        }
        text.replace(at, end - at, kWords[pos(sizeof(kWords) / sizeof(kWords[0]))]);
        break;
      }
      case 5: {  // change a digit
        const std::size_t at = pos(text.size());
        const std::size_t digit = text.find_first_of("0123456789", at);
        if (digit != std::string::npos) {
          text[digit] = static_cast<char>('0' + pos(10));
        }
        break;
      }
      default: {  // move a chunk (reorders statements, e.g. TIED before MOVE)
        const std::size_t a = pos(text.size());
        const std::size_t n = 1 + pos(200);
        const std::string chunk = text.substr(a, n);
        text.erase(a, n);
        text.insert(pos(text.size() + 1), chunk);
        break;
      }
    }
  }
  return text;
}

// Bounded random-mutation fuzzing (issue 8, "Bad input"): thousands of mutated versions of the
// Appendix V program, deterministic seed. Every one must compile or fail without crashing, and
// every diagnostic must carry a position. Programs that still compile are also run with the
// thesis's readings (which may no longer match: that must be a clean error too).
TEST(Fuzz, MutatedAppendixVNeverCrashesAndEveryDiagnosticHasAPosition) {
  const std::string original = read(testing::source_path("config/rapt/appendix_v.rapt"));
  ASSERT_FALSE(original.empty());
  const std::vector<Reading> readings = testing::appendix_v_readings();
  std::mt19937 rng(20240808);
  int compiled = 0;
  int failed = 0;
  constexpr int kCases = 3000;
  for (int i = 0; i < kCases; ++i) {
    const std::string text = mutate(original, rng);
    Diagnostics diags("fuzz.rapt");
    auto cp = compile(text, "fuzz.rapt", diags);
    for (const Diagnostic& d : diags.items()) {
      ASSERT_TRUE(d.loc.known()) << "case " << i << ": no position for: " << d.message
                                 << "\n--- program ---\n"
                                 << text;
    }
    if (cp) {
      ++compiled;
      auto r = run(*cp, readings);
      if (!r) {
        EXPECT_FALSE(r.error().message.empty());
      }
    } else {
      ++failed;
      EXPECT_TRUE(diags.has_errors());
      EXPECT_LE(diags.items().size(), Diagnostics::kMaxDiagnostics);
    }
  }
  RecordProperty("compiled", compiled);
  std::printf("fuzz: %d of %d mutated programs compiled\n", compiled, kCases);
  EXPECT_EQ(compiled + failed, kCases);
  EXPECT_GT(failed, kCases / 2);  // the mutations really do break programs
  EXPECT_GT(compiled, 0);         // and some survive (e.g. edits inside remarks)
}

}  // namespace
}  // namespace cell::rapt

// world_bench: how fast the simulated world runs (core/world) and what publishing its ground
// truth costs (core/world wire + core/bus), with 15, 100 and 1000 parts on a table and a belt.
//
//   world_bench [--quick] [--domain N]
//
// Sections (bench/README.md "world"): (1) World::step rate, with and without a robot carrying a
// part (RobotState at 100 Hz, i.e. one update_robot per 10 steps); (2) a gripper closing (the
// capture search over every part); (3) the overlap check of scenes and scatters: every pair
// (naive O(n^2)) against the FootprintGrid broad phase, which must find the same conflicts;
// (4) a seeded scatter; (5) WorldState: conversion to IDL, Writer::write to a matched reader in
// the same process (serialisation + local delivery), the serialised size, and the reader's take
// (deserialisation); (6) one EXCAL-like frame (24 parts) against the 1992 thesis's figures.
// Every timing is the median of 5 runs of plain steady_clock loops. Exit codes: 0 ran, 1 a
// measurement failed (the message says which), 2 bad command line, 3 no DDS participant.
#include <dds/ddsi/ddsi_serdata.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/world/wire.hpp"
#include "cell/world/world.hpp"

namespace {

using namespace cell;
using namespace cell::world;
using Clock = std::chrono::steady_clock;

constexpr int kRuns = 5;

struct Options {
  bool quick = false;
  std::uint32_t domain = 0;
};

/// Median over kRuns of the seconds one call of `body` takes.
double median_seconds(const std::function<void()>& body) {
  std::vector<double> runs;
  for (int r = 0; r < kRuns; ++r) {
    const auto t0 = Clock::now();
    body();
    runs.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
  }
  std::sort(runs.begin(), runs.end());
  return runs[runs.size() / 2];
}

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "world_bench: %s\n", what.c_str());
  std::exit(1);
}

/// A table (1200 x 900 mm) and a 4 m belt beside it, with n parts: half scattered on the table,
/// half on the belt, at least 2 mm apart; a "bench" robot mounted like the 7545.
World make_world(std::uint32_t n) {
  const Catalogue cat = Catalogue::standard();
  const std::string yaml = fmt::format(
      "table: {{height_mm: 750, x_mm: [-600, 600], y_mm: [-450, 450]}}\n"
      "belts:\n"
      "  - {{id: belt1, origin_mm: [700, 0, 760], length_mm: 4000, width_mm: 400,\n"
      "     speed_mm_s: 50, mm_per_count: 0.03835, photocell_at_mm: 2000}}\n"
      "scatter:\n"
      "  - {{count: {}, classes: [dip14, dip8, ic_7x30], x_mm: [-580, 580], y_mm: [-430, 430],\n"
      "     min_separation_mm: 2, seed: 1}}\n"
      "  - {{count: {}, classes: [dip14, dip8, ic_7x30], x_mm: [730, 2600], y_mm: [-180, 180],\n"
      "     min_separation_mm: 2, seed: 2}}\n",
      n - n / 2, n / 2);
  auto scene = parse_scene(yaml, "bench.yaml", cat);
  if (!scene) {
    fail(scene.error().message);
  }
  WorldOptions options;
  options.robots = {{"bench", Eigen::Isometry3d(Eigen::Translation3d(0, 0, 981.51))}};
  auto world = World::create(*scene, cat, options);
  if (!world) {
    fail(world.error().message);
  }
  return std::move(world).value();
}

Eigen::Isometry3d base_T(const World& w, const Eigen::Isometry3d& world_T_tool) {
  return w.options().robots[0].world_T_base.inverse() * world_T_tool;
}

/// Has the bench robot take the first part on the table.
void attach_first(World& w) {
  std::vector<WorldEvent> events;
  for (const auto& p : w.parts()) {
    if (p.support.kind == Support::Kind::kTable) {
      const Eigen::Isometry3d b = base_T(w, p.world_T_grasp());
      (void)w.update_robot("bench", b, GripperState::kOpen, events);
      (void)w.update_robot("bench", b, GripperState::kClosed, events);
      break;
    }
  }
  if (events.empty() || events.back().kind != WorldEvent::Kind::kAttached) {
    fail("the bench robot could not take a part");
  }
}

void section_steps(const Options& o) {
  std::printf("\n(1) World::step, 1 ms steps, belt at 50 mm/s; half the parts on the belt\n");
  std::printf("%8s %14s %14s %18s %14s\n", "parts", "us/step", "steps/s", "+robot us/step",
              "+robot steps/s");
  const int steps = o.quick ? 2000 : 20000;
  for (const std::uint32_t n : {15U, 100U, 1000U}) {
    const World base = make_world(n);
    std::vector<WorldEvent> events;
    events.reserve(4096);
    const double plain = median_seconds([&] {
      World w = base;  // a fresh copy per run: microseconds against the run's milliseconds
      events.clear();
      for (int i = 0; i < steps; ++i) {
        w.step(0.001, events);
      }
    });
    World held = base;
    attach_first(held);
    const double robot = median_seconds([&] {
      World w = held;
      events.clear();
      for (int i = 0; i < steps; ++i) {
        if (i % 10 == 0) {  // RobotState at 100 Hz: the held part follows a circle
          const double a = i * 1e-3;
          Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();
          tool.translation() = Eigen::Vector3d(100 * std::cos(a), 500 + 100 * std::sin(a), 820);
          (void)w.update_robot("bench", base_T(w, tool), GripperState::kClosed, events);
        }
        w.step(0.001, events);
      }
    });
    std::printf("%8u %14.2f %14.0f %18.2f %14.0f\n", n, plain / steps * 1e6, steps / plain,
                robot / steps * 1e6, steps / robot);
  }
}

void section_capture(const Options& o) {
  std::printf("\n(2) A gripper closing: the capture search over every part (open + close)\n");
  std::printf("%8s %14s\n", "parts", "us/close");
  const int cycles = o.quick ? 200 : 2000;
  for (const std::uint32_t n : {15U, 100U, 1000U}) {
    World w = make_world(n);
    std::vector<WorldEvent> events;
    events.reserve(2 * static_cast<std::size_t>(cycles) + 8);
    Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();
    tool.translation() = Eigen::Vector3d(0, 0, 900);  // above everything: every close misses
    const Eigen::Isometry3d b = base_T(w, tool);
    const double t = median_seconds([&] {
      events.clear();
      for (int i = 0; i < cycles; ++i) {
        (void)w.update_robot("bench", b, GripperState::kOpen, events);
        (void)w.update_robot("bench", b, GripperState::kClosed, events);
      }
    });
    std::printf("%8u %14.2f\n", n, t / cycles * 1e6);
  }
}

void section_overlap(const Options& o) {
  std::printf(
      "\n(3) Overlap check of n parts (every pair closer than 2 mm): naive O(n^2) vs "
      "FootprintGrid\n");
  std::printf("%8s %12s %12s %10s %10s\n", "parts", "naive ms", "grid ms", "speedup", "conflicts");
  std::vector<std::uint32_t> sizes = {100, 1000, 5000};
  if (o.quick) {
    sizes = {100, 1000};
  }
  for (const std::uint32_t n : sizes) {
    // Footprints of dip14s at random, dense enough that some conflict.
    std::vector<Footprint> fs;
    std::uint64_t state = 12345;
    auto next = [&]() {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      return static_cast<double>(state >> 11) * 0x1.0p-53;
    };
    const auto dip14 = Catalogue::standard().find("dip14");
    const double side = std::sqrt(static_cast<double>(n)) * 30.0;
    for (std::uint32_t i = 0; i < n; ++i) {
      fs.push_back(place_footprint(dip14->footprint, next() * side, next() * side, next() * 6.28));
    }
    constexpr double kSep = 2.0;
    std::size_t naive_conflicts = 0;
    const double naive = median_seconds([&] {
      naive_conflicts = 0;
      for (std::size_t i = 0; i < fs.size(); ++i) {
        for (std::size_t j = i + 1; j < fs.size(); ++j) {
          naive_conflicts += too_close(fs[i], fs[j], kSep) ? 1 : 0;
        }
      }
    });
    std::size_t grid_conflicts = 0;
    const double grid = median_seconds([&] {
      grid_conflicts = 0;
      FootprintGrid g(50.0);
      for (std::size_t i = 0; i < fs.size(); ++i) {
        g.for_each_candidate(fs[i], kSep, [&](std::size_t j) {
          grid_conflicts += too_close(fs[i], fs[j], kSep) ? 1 : 0;
        });
        g.insert(i, fs[i]);
      }
    });
    if (naive_conflicts != grid_conflicts) {
      fail(fmt::format("overlap: the grid found {} conflicts, the naive check {}", grid_conflicts,
                       naive_conflicts));
    }
    std::printf("%8u %12.3f %12.3f %9.1fx %10zu\n", n, naive * 1e3, grid * 1e3, naive / grid,
                naive_conflicts);
  }
}

void section_scatter(const Options& o) {
  std::printf("\n(4) Scatter (seeded, 5.7 mm apart, whole parts on the table)\n");
  std::printf("%8s %12s\n", "parts", "ms");
  std::vector<std::uint32_t> sizes = {15, 100, 1000};
  if (o.quick) {
    sizes = {15, 100};
  }
  const World empty = make_world(0);
  for (const std::uint32_t n : sizes) {
    ScatterSpec spec;
    spec.count = n;
    spec.classes = {"dip14", "dip8", "ic_7x30"};
    spec.x_min_mm = -580;
    spec.x_max_mm = 580;
    spec.y_min_mm = -430;
    spec.y_max_mm = 430;
    spec.min_separation_mm = 5.7;
    spec.seed = 3;
    const double t = median_seconds([&] {
      World w = empty;
      if (!w.scatter(spec)) {
        fail("scatter failed");
      }
    });
    std::printf("%8u %12.3f\n", n, t * 1e3);
  }
}

struct StateCost {
  double fill_us = 0;
  double write_us = 0;
  double take_us = 0;
  std::uint32_t bytes = 0;
};

StateCost state_cost(const World& w, bus::Participant& participant, int reps) {
  bus::Topic<cell_world_WorldState> topic(participant, bus::topics::kWorldState);
  bus::Writer<cell_world_WorldState> writer(participant, topic, bus::topics::kWorldState);
  bus::Reader<cell_world_WorldState> reader(participant, topic, bus::topics::kWorldState);
  if (!writer.wait_for_readers(1, std::chrono::seconds(5))) {
    fail("WorldState: the local reader did not match");
  }
  WorldStateWire wire;
  StateCost c;
  std::uint64_t seq = 0;
  c.fill_us = median_seconds([&] {
                for (int i = 0; i < reps; ++i) {
                  fill_world_state(w, 1, ++seq, wire);
                }
              }) /
              reps * 1e6;
  fill_world_state(w, 1, ++seq, wire);
  // Size: write once, take the serialised sample.
  if (!writer.write(wire.message)) {
    fail("WorldState write failed");
  }
  struct ddsi_serdata* sd = nullptr;
  dds_sample_info_t info{};
  if (dds_takecdr(reader.get(), &sd, 1, &info, DDS_ANY_STATE) != 1) {
    fail("WorldState: nothing to take after a write");
  }
  c.bytes = ddsi_serdata_size(sd);
  ddsi_serdata_unref(sd);
  c.write_us = median_seconds([&] {
                 for (int i = 0; i < reps; ++i) {
                   if (!writer.write(wire.message)) {
                     fail("WorldState write failed");
                   }
                 }
               }) /
               reps * 1e6;
  c.take_us = median_seconds([&] {
                for (int i = 0; i < reps; ++i) {
                  (void)writer.write(wire.message);
                  auto got = reader.take_copies(1);
                  if (!got || got->size() != 1) {
                    fail("WorldState: the local reader got nothing");
                  }
                }
              }) / reps *
                  1e6 -
              c.write_us;
  return c;
}

void section_state(const Options& o, bus::Participant& participant) {
  std::printf(
      "\n(5) WorldState (topic cell/world/state, QoS stream keep-last 1) with a matched "
      "reader in this process\n");
  std::printf("%8s %12s %12s %14s %12s %14s\n", "parts", "bytes", "fill us", "write us", "take us",
              "fill+write/s");
  const int reps = o.quick ? 50 : 500;
  for (const std::uint32_t n : {15U, 100U, 1000U}) {
    const World w = make_world(n);
    const StateCost c = state_cost(w, participant, n >= 1000 ? std::max(5, reps / 10) : reps);
    std::printf("%8u %12u %12.2f %14.2f %12.2f %14.0f\n", n, c.bytes, c.fill_us, c.write_us,
                c.take_us, 1e6 / (c.fill_us + c.write_us));
  }
}

void section_excal(const Options& o, bus::Participant& participant) {
  // Digest 001 §6, Tables 3-4: EXCAL on a 486/33 needed 0.062 s of CPU per image (of which
  // 0.001 s collision check and 0.013 s transformations) and 0.07 s (normal view) to 0.22 s
  // (gripper-follow view) of display time per frame with 24 objects. The nearest work here is
  // one frame of world update for 24 parts (10 steps + a robot update = 10 ms of world time)
  // plus publishing the WorldState a renderer draws from; the drawing itself is the renderer's.
  const int frames = o.quick ? 200 : 2000;
  World w = make_world(24);
  attach_first(w);
  std::vector<WorldEvent> events;
  events.reserve(1024);
  const double update =
      median_seconds([&] {
        World copy = w;
        for (int f = 0; f < frames; ++f) {
          Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();
          tool.translation() = Eigen::Vector3d(100, 500 + f * 0.01, 820);
          (void)copy.update_robot("bench", base_T(copy, tool), GripperState::kClosed, events);
          for (int s = 0; s < 10; ++s) {
            copy.step(0.001, events);
          }
          events.clear();
        }
      }) /
      frames;
  const StateCost c = state_cost(w, participant, o.quick ? 50 : 500);
  const double frame_s = update + (c.fill_us + c.write_us) * 1e-6;
  std::printf("\n(6) One frame with 24 parts (as EXCAL's Table 4, digest 001 §6)\n");
  std::printf(
      "  world update (robot + 10 steps): %.2f us; WorldState fill + write: %.2f us; "
      "frame: %.2f us\n",
      update * 1e6, c.fill_us + c.write_us, frame_s * 1e6);
  std::printf(
      "  EXCAL 486/33, 24 objects: 0.07 s (normal view) .. 0.22 s (gripper-follow) per "
      "frame, of which ~0.014 s transformations + collision check (Table 3)\n");
  std::printf(
      "  ratio to EXCAL's 0.07 s: %.0fx; to its 0.014 s of world computation: %.0fx "
      "(different work: EXCAL drew the frame too)\n",
      0.07 / frame_s, 0.014 / (update + 1e-12));
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  const char* env_domain = std::getenv("CELL_DOMAIN_ID");
  o.domain = env_domain != nullptr ? static_cast<std::uint32_t>(std::atoi(env_domain))
                                   : 150U + static_cast<std::uint32_t>(getpid() % 80);
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      o.quick = true;
    } else if (a == "--domain" && i + 1 < argc) {
      o.domain = static_cast<std::uint32_t>(std::atoi(argv[++i]));
    } else if (a == "--help" || a == "-h") {
      std::printf(
          "world_bench [--quick] [--domain N]: core/world step rate, capture, overlap, "
          "scatter and WorldState costs (bench/README.md)\n");
      return 0;
    } else {
      std::fprintf(stderr, "world_bench: unknown argument '%s' (try --help)\n", a.c_str());
      return 2;
    }
  }
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI", CELL_BENCH_DDS_URI, 1);
  }
  std::printf("world_bench%s: median of %d runs; 2-core VM shared with builds\n",
              o.quick ? " --quick" : "", kRuns);
  section_steps(o);
  section_capture(o);
  section_overlap(o);
  section_scatter(o);
  try {
    bus::Participant participant(o.domain, fmt::format("bench-{}", getpid()));
    section_state(o, participant);
    section_excal(o, participant);
  } catch (const bus::BusError& e) {
    std::fprintf(stderr, "world_bench: no DDS participant: %s\n", e.what());
    return 3;
  }
  std::printf("\nworld_bench: done\n");
  return 0;
}

#pragma once
// Built-in layout: the Inspire FTP hand (DECO-50, paper Sec. IV-A), its regions as in the reference
// implementation (E-Kovtun/tactile, tactile_ssl/data/deco_geometry.py). 1062 taxels per hand in 17
// regions; two hands give 2124 taxels in two parts ("left", "right") that are not connected.
//
// Region order inside a hand (the order of the hand's tactile registers): little, ring, middle,
// index (each: tip 3x3, nail 12x8, pad 10x8), thumb (tip 3x3, nail 12x8, middle 3x3, pad 12x8),
// palm 8x14. Inside a region, cells row-major from row 0 (row 0 nearest the palm; for the palm,
// nearest the wrist). Two hands: the left hand's 1062 taxels, then the right hand's.
//
// Edges: 4-neighbour grid edges inside each region, and k = 4 bridges (closest cross-region taxel
// pairs) between the 16 adjacent region pairs of a hand: along each finger tip-nail-pad-palm, along
// the thumb tip-nail-middle-pad-palm. Weights: distances in mm.
//
// Coordinates (mm, x right, y up): an invented flat drawing, not the hand's CAD. Finger regions at
// 1.6 mm pitch, palm at 5 mm; fingers as columns 18 mm apart above the palm, the thumb tilted to
// the side; the right hand is the left hand mirrored, drawn 200 mm to its right.
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "tjepa/graph/block_grouping.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/join.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/layout_builder.hpp"

namespace tjepa::layouts {

namespace inspire {
inline constexpr int kTaxelsPerHand = 1062;
inline constexpr int kRegionsPerHand = 17;
inline constexpr double kFingerPitch = 1.6;  // mm
inline constexpr double kPalmPitch = 5.0;

enum class Side { left, right };

struct Region {
  std::string name;
  int rows, cols;
};

// The 17 regions of a hand in taxel order.
inline std::vector<Region> regions() {
  std::vector<Region> r;
  for (const char* f : {"little", "ring", "middle", "index"}) {
    r.push_back({std::string(f) + "_tip", 3, 3});
    r.push_back({std::string(f) + "_nail", 12, 8});
    r.push_back({std::string(f) + "_pad", 10, 8});
  }
  r.push_back({"thumb_tip", 3, 3});
  r.push_back({"thumb_nail", 12, 8});
  r.push_back({"thumb_middle", 3, 3});
  r.push_back({"thumb_pad", 12, 8});
  r.push_back({"palm", 8, 14});
  return r;
}

// The 16 adjacent region pairs of a hand, by region index.
inline std::vector<GroupPair> adjacent_regions() {
  std::vector<GroupPair> p;
  for (int f = 0; f < 4; ++f) {
    p.push_back({3 * f, 3 * f + 1});
    p.push_back({3 * f + 1, 3 * f + 2});
    p.push_back({3 * f + 2, 16});
  }
  p.push_back({12, 13});
  p.push_back({13, 14});
  p.push_back({14, 15});
  p.push_back({15, 16});
  return p;
}
}  // namespace inspire

// One hand: one part named after its side, 1062 taxels, 17 regions, one component.
inline Skin inspire_hand(inspire::Side side) {
  using namespace inspire;
  const double mirror = side == Side::left ? 1.0 : -1.0;
  LayoutBuilder b(2);
  const int hand = b.add_part(side == Side::left ? "left" : "right");
  const auto reg = regions();
  // Region centres along a finger: each region's centre from the finger's base, gap 3 mm.
  auto along = [](double base_to_first, int k, const std::vector<double>& heights) {
    double y = base_to_first;
    for (int j = 0; j < k; ++j) y += 0.5 * heights[j] + 3.0 + 0.5 * heights[j + 1];
    return y;
  };
  const double palm_top = 0.5 * 7 * kPalmPitch;
  std::size_t r = 0;
  for (int f = 0; f < 4; ++f) {
    // Base to tip: pad (10 rows), nail (12 rows), tip (3 rows); taxel order is tip, nail, pad.
    const std::vector<double> h = {9 * kFingerPitch, 11 * kFingerPitch, 2 * kFingerPitch};
    const double x = mirror * (-27.0 + 18.0 * f);
    const double y0 = palm_top + 5.0 + 0.5 * h[0];
    for (int j = 2; j >= 0; --j, ++r) {
      const GridPad pad(reg[r].rows, reg[r].cols, kFingerPitch);
      b.add_grid_pad(reg[r].name, hand, pad, {x, along(y0, j, h), 0.0});
    }
  }
  {
    // Thumb, tilted 40° away from the fingers, from the palm's side: pad, middle, nail, tip.
    const std::vector<double> h = {11 * kFingerPitch, 2 * kFingerPitch, 11 * kFingerPitch, 2 * kFingerPitch};
    const double angle = -40.0 * mirror, th = angle * std::numbers::pi / 180.0;
    const double dx = -std::sin(th), dy = std::cos(th);
    const double x0 = mirror * 46.0, y0 = -10.0;
    for (int j = 3; j >= 0; --j, ++r) {
      const GridPad pad(reg[r].rows, reg[r].cols, kFingerPitch);
      const double t = along(0.0, j, h);
      b.add_grid_pad(reg[r].name, hand, pad, {x0 + t * dx, y0 + t * dy, angle});
    }
  }
  b.add_grid_pad(reg[r].name, hand, GridPad(8, 14, kPalmPitch), {0.0, 0.0, 0.0});
  b.add_bridges(adjacent_regions(), 4);
  return b.build();
}

// Both hands: 2124 taxels, parts "left" (taxels 0..1061) and "right", regions "left/palm" etc.,
// two components. The right hand is drawn 200 mm to the right of the left.
inline Skin inspire_hands() {
  Skin right = inspire_hand(inspire::Side::right);
  for (int i = 0; i < right.size(); ++i) right.layout.coords[2 * i] += 200.0;
  const Skin hands[2] = {inspire_hand(inspire::Side::left), std::move(right)};
  const std::string names[2] = {"left", "right"};
  return join_skins(hands, names);
}

// DECO-50 grouping of one or two Inspire hands: block_grouping (2 x 2 blocks, 3 x 3 regions as
// 4 + 5): 264 tokens per hand (528 for two), sizes 4 and 5, the group graph with unit weights.
inline Grouping deco50_grouping(const Skin& hands) { return block_grouping(hands, GroupWeights::unit); }

}  // namespace tjepa::layouts

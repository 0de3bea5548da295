#pragma once
// The objects SimulatedHand grasps, and the grasp types (docs/grasping_hand.md §2-3). Each object
// has the contact shape it presses into a pad (one of the contact model's lobe patterns), its size,
// mass, object–skin friction and the grasps it allows.
#include <cstdint>
#include <string>
#include <vector>

#include "tjepa/sim/contact_model.hpp"

namespace tjepa {

// Which pads touch (docs/grasping_hand.md §3).
enum class GraspType : int { pinch = 0, lateral = 1, tripod = 2, precision = 3, power = 4 };
inline constexpr int num_grasp_types = 5;
inline const char* grasp_name(int grasp) {
  static const char* names[] = {"pinch", "lateral", "tripod", "precision", "power"};
  return grasp >= 0 && grasp < num_grasp_types ? names[grasp] : "none";
}

struct GraspObject {
  std::string name;
  IndenterShape shape;       // the pattern it presses into a pad
  double contact_size;       // mm: sphere radius, flat radius, edge half-length on a pad, multi-point spread
  double edge_radius;        // mm, an edge's ridge radius (cylinders: their radius)
  int points;                // multi-point: number of points
  double radius;             // mm, half the object's smallest width across the grasp
  double length;             // mm, along its long axis
  double mass;               // kg
  double friction;           // μ, object against the skin
  std::uint32_t grasps;      // bit g set: GraspType g allowed

  bool allows(GraspType g) const { return (grasps >> static_cast<int>(g)) & 1u; }
  double weight(double gravity) const { return mass * gravity; }  // N
};

namespace detail {
inline constexpr std::uint32_t grasp_bit(GraspType g) { return 1u << static_cast<int>(g); }
}  // namespace detail

// The 16 objects of docs/grasping_hand.md §2; an object's id is its index.
inline const std::vector<GraspObject>& grasp_objects() {
  using S = IndenterShape;
  constexpr auto pinch = detail::grasp_bit(GraspType::pinch), lateral = detail::grasp_bit(GraspType::lateral),
                 tripod = detail::grasp_bit(GraspType::tripod), precision = detail::grasp_bit(GraspType::precision),
                 power = detail::grasp_bit(GraspType::power);
  static const std::vector<GraspObject> objects = {
      // name, shape, contact size, ridge radius, points, radius, length (mm), mass (kg), μ, grasps
      {"marble", S::sphere, 8.0, 1.0, 3, 8.0, 16.0, 0.005, 0.3, pinch | tripod},
      {"small_ball", S::sphere, 12.0, 1.0, 3, 12.0, 24.0, 0.010, 0.9, pinch | tripod},
      {"golf_ball", S::sphere, 21.0, 1.0, 3, 21.0, 42.0, 0.046, 0.5, pinch | tripod | precision},
      {"tennis_ball", S::sphere, 33.0, 1.0, 3, 33.0, 66.0, 0.058, 0.8, tripod | precision | power},
      {"apple", S::sphere, 40.0, 1.0, 3, 40.0, 80.0, 0.180, 0.6, precision | power},
      {"pen", S::edge, 12.0, 4.5, 3, 4.5, 140.0, 0.012, 0.4, pinch | tripod | lateral},
      {"can", S::edge, 12.0, 33.0, 3, 33.0, 120.0, 0.370, 0.5, power},
      {"bottle", S::edge, 12.0, 35.0, 3, 35.0, 200.0, 0.500, 0.6, power},
      {"mug_handle", S::edge, 10.0, 6.0, 3, 6.0, 50.0, 0.320, 0.5, lateral | tripod},
      {"wedge", S::edge, 12.0, 1.0, 3, 15.0, 80.0, 0.040, 0.7, pinch | tripod},
      {"box", S::flat, 8.0, 1.0, 3, 20.0, 100.0, 0.150, 0.6, precision | power},
      {"cube", S::flat, 6.0, 1.0, 3, 15.0, 30.0, 0.025, 0.7, pinch | tripod | precision},
      {"coin", S::flat, 11.0, 1.0, 3, 12.0, 24.0, 0.007, 0.3, pinch | lateral},
      {"puck", S::flat, 12.0, 1.0, 3, 38.0, 76.0, 0.165, 0.6, precision | power},
      {"ring", S::multi_point, 10.0, 1.0, 12, 10.0, 20.0, 0.004, 0.4, pinch | lateral},
      {"lego_brick", S::multi_point, 5.7, 1.0, 4, 8.0, 16.0, 0.0025, 0.5, pinch | tripod},
  };
  return objects;
}

inline int num_grasp_objects() { return static_cast<int>(grasp_objects().size()); }

}  // namespace tjepa

#pragma once
// SimulatedHand: the Xela uSkin on the Allegro hand (layouts::allegro_xela(), 368 taxels in 18
// pads, 3 axes, 100 Hz) grasping objects in episodes like teleoperated play: idle (sometimes an
// incidental touch), reach, grasp, lift, 2-4 actions (re-grasp, in-hand rotate, slide, hold),
// place, release; then the next object. The physics and the episode model are fixed in
// docs/grasping_hand.md; in short:
//   * An object (grasp_objects.hpp: 16 objects, shape, size, mass, μ) is held with one of the
//     grasps it allows; the grasp decides which pads touch and each pad's share of the grip.
//   * The object's pose (x, y cm, θ degrees) decides where each contact sits on its pad:
//     P_k + d + (R(θ) − I)·ℓ_k (nominal point, displacement, rotation of the lever), and the
//     pattern's orientation ψ_k + θ.
//   * Grip F_grip = max(1 N, s·W/μ), s ~ U(1.4, 2.2) per episode, shared by the contacts; while
//     lifted the weight W = m·g is carried as shear along gravity (in-plane angle γ per episode)
//     in proportion to each contact's normal force; moving contacts add 0.5·μ·F_k along their
//     motion; the shear lags its target and never exceeds μ·F_k.
//   * Each contact renders through the contact model shared with SimulatedSkin (contact_model.hpp)
//     into raw Xela-like counts, so PreprocessConfig::xela_counts() with a baseline applies.
// Labels per frame (GraspLabel): episode, object, grasp, phase, held, pose, the 3-axis force on
// one pad (GraspSimConfig::label_pad, the FrameLabel convention) and the 18-bit contact mask.
//
// Everything is drawn from one tjepa::Rng seeded at construction: the same config, seed and
// sequence of calls give the same data bit for bit.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/sensors/allegro_xela.hpp"
#include "tjepa/layout/taxel_layout.hpp"
#include "tjepa/sim/contact_model.hpp"
#include "tjepa/sim/grasp_objects.hpp"

namespace tjepa {

// The episode's phase (docs/grasping_hand.md §6).
enum class GraspPhase : int { idle = 0, touch, reach, grasp, lift, regrasp, rotate, slide, hold, place, release };
inline constexpr int num_grasp_phases = 11;
inline const char* grasp_phase_name(int phase) {
  static const char* names[] = {"idle", "touch", "reach", "grasp", "lift", "regrasp",
                                "rotate", "slide", "hold", "place", "release"};
  return phase >= 0 && phase < num_grasp_phases ? names[phase] : "none";
}

// One frame's ground truth.
struct GraspLabel {
  int episode = -1;     // the frame's episode: counts the episodes the SimulatedHand started, from 0
  int episode_object = -1;  // the object of the frame's episode (also in its idle, touch and reach)
  int object = -1;      // object id (grasp_objects()), -1: nothing in the hand
  int grasp = -1;       // GraspType, -1: none
  int phase = 0;        // GraspPhase
  bool held = false;    // the object is lifted (lift and the actions)
  float x_cm = 0.0f, y_cm = 0.0f, theta_deg = 0.0f;  // pose while an object is in the hand, else 0
  std::array<float, 3> force{};  // N on GraspSimConfig::label_pad: (shear u, shear v, normal), 0 if free
  std::uint32_t contact_mask = 0;  // bit p: pad p in contact (normal >= contact_threshold)
};

struct GraspRecording {
  Recording recording;             // [T, 368, axes] raw counts
  std::vector<GraspLabel> labels;  // [T]
};

// The physics fields (rate, axes, elastomer, sensor) come from SkinPhysics with SimConfig's
// defaults; the rest are docs/grasping_hand.md's numbers. Frames are at rate_hz.
struct GraspSimConfig : SkinPhysics {
  int label_pad = 3;                 // pad whose force the labels carry (3: index_tip)
  double gravity = 9.81;             // m/s²
  double safety_min = 1.4, safety_max = 2.2;  // grip / slip-limit grip, per episode
  double grip_min = 1.0;             // N, smallest total grip
  double contact_threshold = 0.05;   // N: below it a contact is not rendered nor labelled
  double motion_traction = 0.5;      // × μ·F_k along a contact's motion on its pad
  double max_offset_cm = 0.6;        // |x|, |y| range of the pose
  double max_theta_deg = 30.0;       // |θ| range of the pose
  double start_offset_cm = 0.3, start_theta_deg = 10.0;  // ranges of the pose at grasp
  double touch_probability = 0.5;    // incidental touch after an idle phase
  double touch_force_min = 0.1, touch_force_max = 3.0;  // N, log-uniform
  double touch_friction = 0.6;
  int idle_frames_min = 20, idle_frames_max = 100;
  int reach_frames_min = 30, reach_frames_max = 80;
  int ramp_frames_min = 8, ramp_frames_max = 25;  // a contact going on or off
  int onset_delay_max = 20;          // frames, a contact's delay within grasp, release, re-grasp
  int lift_frames_min = 20, lift_frames_max = 50;
  int actions_min = 2, actions_max = 4;
  int off_frames_min = 5, off_frames_max = 20;     // a re-grasping finger in the air
  int rotate_frames_min = 40, rotate_frames_max = 120;
  int slide_frames_min = 40, slide_frames_max = 120;
  int hold_frames_min = 30, hold_frames_max = 150;
  int place_frames_min = 15, place_frames_max = 40;
  int touch_ramp_frames_min = 5, touch_ramp_frames_max = 20;
  int touch_hold_frames_min = 5, touch_hold_frames_max = 40;

  void validate() const {
    validate_physics("GraspSimConfig");
    auto pos = [](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v > 0, "GraspSimConfig: ", name, " = ", v, ", expected > 0");
    };
    auto frames = [](int lo, int hi, int least, const char* name) {
      require<ConfigError>(lo >= least && lo <= hi, "GraspSimConfig: ", name, " range [", lo, ", ", hi,
                           "], expected ", least, " <= min <= max");
    };
    require<ConfigError>(label_pad >= 0 && label_pad < layouts::allegro::kPads, "GraspSimConfig: label_pad = ",
                         label_pad, ", expected in [0, ", layouts::allegro::kPads, ")");
    pos(gravity, "gravity");
    require<ConfigError>(safety_min >= 1 && safety_min <= safety_max && std::isfinite(safety_max),
                         "GraspSimConfig: safety range [", safety_min, ", ", safety_max,
                         "], expected 1 <= min <= max (a grip below the slip limit drops the object)");
    pos(grip_min, "grip_min");
    pos(contact_threshold, "contact_threshold");
    require<ConfigError>(motion_traction >= 0 && motion_traction <= 1, "GraspSimConfig: motion_traction = ",
                         motion_traction, ", expected in [0, 1]");
    pos(max_offset_cm, "max_offset_cm");
    pos(max_theta_deg, "max_theta_deg");
    require<ConfigError>(start_offset_cm >= 0 && start_offset_cm <= max_offset_cm, "GraspSimConfig: start_offset_cm = ",
                         start_offset_cm, ", expected in [0, max_offset_cm = ", max_offset_cm, "]");
    require<ConfigError>(start_theta_deg >= 0 && start_theta_deg <= max_theta_deg, "GraspSimConfig: start_theta_deg = ",
                         start_theta_deg, ", expected in [0, max_theta_deg = ", max_theta_deg, "]");
    require<ConfigError>(touch_probability >= 0 && touch_probability <= 1, "GraspSimConfig: touch_probability = ",
                         touch_probability, ", expected in [0, 1]");
    pos(touch_force_min, "touch_force_min");
    require<ConfigError>(touch_force_min <= touch_force_max, "GraspSimConfig: touch force range [", touch_force_min,
                         ", ", touch_force_max, "], expected min <= max");
    require<ConfigError>(touch_friction >= 0 && touch_friction <= 2, "GraspSimConfig: touch_friction = ",
                         touch_friction, ", expected in [0, 2]");
    frames(idle_frames_min, idle_frames_max, 0, "idle_frames");
    frames(reach_frames_min, reach_frames_max, 0, "reach_frames");
    frames(ramp_frames_min, ramp_frames_max, 1, "ramp_frames");
    frames(0, onset_delay_max, 0, "onset_delay");
    frames(lift_frames_min, lift_frames_max, 1, "lift_frames");
    frames(actions_min, actions_max, 0, "actions");
    frames(off_frames_min, off_frames_max, 1, "off_frames");
    frames(rotate_frames_min, rotate_frames_max, 1, "rotate_frames");
    frames(slide_frames_min, slide_frames_max, 1, "slide_frames");
    frames(hold_frames_min, hold_frames_max, 1, "hold_frames");
    frames(place_frames_min, place_frames_max, 1, "place_frames");
    frames(touch_ramp_frames_min, touch_ramp_frames_max, 1, "touch_ramp_frames");
    frames(touch_hold_frames_min, touch_hold_frames_max, 0, "touch_hold_frames");
  }
};

class SimulatedHand {
 public:
  // One pad's contact with the object held (or the incidental touch) at the current frame, after
  // the contact threshold: what was rendered.
  struct Contact {
    ContactState state;
    double friction;  // μ of that contact
  };

  SimulatedHand(const TaxelLayout& layout, GraspSimConfig config = {}, std::uint64_t seed = 0)
      : cfg_(std::move(config)), rng_(seed) {
    cfg_.validate();
    require<ConfigError>(layout.group_names == layouts::allegro::pad_names() &&
                             layout.size() == layouts::allegro::kTaxels,
                         "SimulatedHand: the layout has ", layout.size(), " taxels in ", layout.num_groups(),
                         " pads, expected the Allegro/Xela layout (layouts::allegro_xela(): ",
                         layouts::allegro::kTaxels, " taxels, ", layouts::allegro::kPads, " pads)");
    geo_ = SkinGeometry::from_layout(layout);
    geo_.validate("SimulatedHand");
    pads_ = PadFrames(geo_);
    sensor_ = SkinSensor(cfg_, geo_.size(), rng_);
    // Each finger's direction (layout, unit): from its first phalanx pad to its tip pad.
    for (int tip : {kThumbTip, kIndexTip, kMiddleTip, kRingTip}) {
      const auto& a = pads_[tip + 1].origin;
      const auto& b = pads_[tip].origin;
      const double dx = b[0] - a[0], dy = b[1] - a[1], n = std::hypot(dx, dy);
      finger_dir_[tip] = {dx / n, dy / n};
    }
  }

  // New episodes (objects, grasps, noise, drift steps, drop-outs) from `seed`, on the same sensor:
  // offsets, gains and the drift's state are kept, so a baseline recorded before still applies.
  // The episode in progress is dropped; the next frame starts a new one.
  void reseed(std::uint64_t seed) {
    rng_ = Rng(seed, 0x68616e64ull /* "hand" */);
    ep_ = Episode{};
    deck_.clear();
  }

  const GraspSimConfig& config() const { return cfg_; }
  const SkinGeometry& geometry() const { return geo_; }
  const PadFrames& pads() const { return pads_; }
  int taxels() const { return geo_.size(); }
  int axes() const { return cfg_.axes; }
  int num_pads() const { return pads_.size(); }
  // Per-taxel reading with no contact, no noise and no drift: [N, axes] counts.
  const std::vector<float>& offsets() const { return sensor_.offsets(); }
  // The contacts rendered in the last frame recorded (by record()).
  const std::vector<Contact>& contacts() const { return contacts_; }

  // A contact-free recording of the same sensor (for fitting the preprocessing baseline).
  Recording record_baseline(int frames) {
    require<ConfigError>(frames >= 0, "SimulatedHand::record_baseline: frames = ", frames, ", expected >= 0");
    return sensor_.record_baseline(rng_, frames, "simulated hand (no contact)");
  }

  // `frames` frames of grasping play and their labels. Successive calls continue the same episode
  // and sensor.
  GraspRecording record(int frames) {
    require<ConfigError>(frames >= 0, "SimulatedHand::record: frames = ", frames, ", expected >= 0");
    GraspRecording out;
    out.recording = Recording(frames, taxels(), axes());
    out.recording.set_source("simulated hand");
    out.labels.resize(static_cast<std::size_t>(frames));
    float* x = out.recording.mutable_data();
    for (int t = 0; t < frames; ++t) {
      float* f = x + static_cast<std::size_t>(t) * taxels() * axes();
      sensor_.noise_frame(rng_, f);
      GraspLabel& l = out.labels[static_cast<std::size_t>(t)];
      step(l);
      for (const Contact& c : contacts_) {
        sensor_.add_contact(pads_, c.state, f);
        l.contact_mask |= 1u << c.state.pad;
        if (c.state.pad == cfg_.label_pad)
          l.force = {static_cast<float>(c.state.shear_u), static_cast<float>(c.state.shear_v),
                     static_cast<float>(c.state.normal)};
      }
      sensor_.apply_dropouts(rng_, f);
    }
    return out;
  }

 private:
  static constexpr int kThumbTip = 0, kIndexTip = 3, kMiddleTip = 7, kRingTip = 11, kPalm0 = 15;
  static constexpr double kDeg = std::numbers::pi / 180.0;
  static constexpr double kMaxLever = 12.0;  // mm

  // One pad's contact with the object, for the whole episode.
  struct Grip {
    int pad = 0;
    double share = 0;            // of the grip's normal force
    double u0 = 0, v0 = 0;       // mm, nominal point on the pad (pose 0)
    double lever_x = 0, lever_y = 0;  // mm, ℓ_k in the layout's plane
    double psi = 0;              // rad, pattern orientation at θ = 0
    double activation = 1;       // in [0, 1]: on the object (re-grasp lifts it)
    // Per contact state, reset when the contact is lost.
    double shear_u = 0, shear_v = 0, u_prev = 0, v_prev = 0;
    bool touching = false;
    // Timing within the current grasp, release or re-grasp segment.
    int delay = 0, down = 0, off = 0, up = 0;
    bool regrasping = false;
    double u_new = 0, v_new = 0;  // re-grasp: the nominal point it comes back to
  };
  struct Segment {
    GraspPhase phase = GraspPhase::idle;
    int frames = 0;
    double x_to = 0, y_to = 0, theta_to = 0;  // rotate, slide: the pose at the end (cm, degrees)
  };
  struct Touch {  // an incidental contact
    ContactState shape;
    double peak = 0, dir = 0, frac = 0;
    int ramp = 1, hold = 0, release = 1;
    double shear_u = 0, shear_v = 0;
  };
  struct Episode {
    std::vector<Segment> segments;
    std::size_t seg = 0;
    int k = 0;        // frame within the segment
    int frame = 0;    // frame within the episode
    int id = -1;      // GraspLabel::episode
    int object = -1;
    GraspType grasp = GraspType::pinch;
    std::vector<Grip> grips;
    Touch touch;
    double grip = 0, weight = 0, mu = 1, gravity_angle = 0, fluct_period = 50, fluct_phase = 0;
    double x = 0, y = 0, theta = 0;            // pose now (cm, degrees)
    double x_from = 0, y_from = 0, theta_from = 0;  // at the start of the segment
  };

  int range(int lo, int hi) { return lo + static_cast<int>(rng_.below(static_cast<std::uint64_t>(hi - lo + 1))); }

  int next_object() {
    if (deck_.empty()) {
      for (int i = num_grasp_objects() - 1; i >= 0; --i) deck_.push_back(i);
      rng_.shuffle(std::span<int>(deck_));
    }
    const int o = deck_.back();
    deck_.pop_back();
    return o;
  }

  // The pads a grasp of object o uses, and their base shares (before the per-episode jitter).
  void grasp_pads(const GraspObject& o, GraspType g, std::vector<int>& pads, std::vector<double>& share) {
    pads.clear();
    share.clear();
    auto add = [&](std::initializer_list<int> ps, double each) {
      for (int p : ps) {
        pads.push_back(p);
        share.push_back(each);
      }
    };
    switch (g) {
      case GraspType::pinch: add({kThumbTip, kIndexTip}, 0.5); break;
      case GraspType::lateral: add({kThumbTip, kIndexTip + 1}, 0.5); break;
      case GraspType::tripod:
        add({kThumbTip}, 0.5);
        add({kIndexTip, kMiddleTip}, 0.25);
        break;
      case GraspType::precision:
        add({kThumbTip}, 0.4);
        add({kIndexTip, kMiddleTip, kRingTip}, 0.2);
        break;
      case GraspType::power: {
        const bool big = o.radius >= 30.0, long_ = o.length >= 100.0;
        const bool ring = rng_.uniform() < 0.7;
        std::vector<int> thumb = {kThumbTip, kThumbTip + 1}, rest;
        if (big) thumb.push_back(kThumbTip + 2);
        for (int tip : {kIndexTip, kMiddleTip, kRingTip}) {
          if (tip == kRingTip && !ring) continue;
          for (int j = 0; j < (big ? 4 : 3); ++j) rest.push_back(tip + j);
        }
        rest.push_back(kPalm0);
        rest.push_back(kPalm0 + 1);
        if (long_) rest.push_back(kPalm0 + 2);
        for (int p : thumb) add({p}, 0.4 / static_cast<double>(thumb.size()));
        for (int p : rest) add({p}, 0.6 / static_cast<double>(rest.size()));
        break;
      }
    }
  }

  // The nominal contact point of pad p in a grasp of type g: the pad's centre, the finger pulp for
  // fingertips, jittered.
  std::array<double, 2> nominal_point(int p, GraspType g) {
    double u = 0, v = 0;
    if (p == kThumbTip || p == kIndexTip || p == kMiddleTip || p == kRingTip) {
      const double along = g == GraspType::power ? -3.0 : 4.0;
      const auto& d = finger_dir_[p];
      const auto& P = pads_[p];
      u += along * (d[0] * P.eu[0] + d[1] * P.eu[1]);
      v += along * (d[0] * P.ev[0] + d[1] * P.ev[1]);
    }
    u += rng_.uniform(-2.0, 2.0);
    v += rng_.uniform(-2.0, 2.0);
    return {u, v};
  }

  // Lengths of a contact going on (or off): delay then ramp.
  void draw_onset(Grip& g) {
    g.delay = range(0, cfg_.onset_delay_max);
    g.up = range(cfg_.ramp_frames_min, cfg_.ramp_frames_max);
  }

  void start_episode() {
    Episode& e = ep_;
    e = Episode{};
    e.id = episodes_++;
    auto seg = [&](GraspPhase p, int frames) {
      Segment s;
      s.phase = p;
      s.frames = frames;
      e.segments.push_back(s);
    };
    seg(GraspPhase::idle, range(cfg_.idle_frames_min, cfg_.idle_frames_max));
    if (rng_.uniform() < cfg_.touch_probability) {
      Touch& t = e.touch;
      const GraspObject& like = grasp_objects()[rng_.below(grasp_objects().size())];
      t.shape = object_contact(like);
      t.shape.pad = pads_.live_pads()[rng_.below(pads_.live_pads().size())];
      const PadFrames::Pad& P = pads_[t.shape.pad];
      const int i = P.taxels[rng_.below(P.taxels.size())];
      t.shape.u = pads_.u(i) + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
      t.shape.v = pads_.v(i) + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
      t.shape.orientation = rng_.uniform(0.0, std::numbers::pi);
      t.peak = std::exp(rng_.uniform(std::log(cfg_.touch_force_min), std::log(cfg_.touch_force_max)));
      t.frac = rng_.uniform(0.0, 0.4) * cfg_.touch_friction;
      t.dir = rng_.uniform(0.0, 2.0 * std::numbers::pi);
      t.ramp = range(cfg_.touch_ramp_frames_min, cfg_.touch_ramp_frames_max);
      t.hold = range(cfg_.touch_hold_frames_min, cfg_.touch_hold_frames_max);
      t.release = range(cfg_.touch_ramp_frames_min, cfg_.touch_ramp_frames_max);
      seg(GraspPhase::touch, t.ramp + t.hold + t.release);
    }
    seg(GraspPhase::reach, range(cfg_.reach_frames_min, cfg_.reach_frames_max));

    // The object, the grasp and its contacts.
    e.object = next_object();
    const GraspObject& o = grasp_objects()[static_cast<std::size_t>(e.object)];
    std::vector<GraspType> allowed;
    for (int g = 0; g < num_grasp_types; ++g)
      if (o.allows(static_cast<GraspType>(g))) allowed.push_back(static_cast<GraspType>(g));
    e.grasp = allowed[rng_.below(allowed.size())];
    std::vector<int> pads;
    std::vector<double> share;
    grasp_pads(o, e.grasp, pads, share);
    double total = 0;
    for (double& s : share) total += (s *= rng_.uniform(0.8, 1.2));
    const double psi0 = e.grasp == GraspType::power ? 0.0 : rng_.uniform(0.0, std::numbers::pi);
    double cx = 0, cy = 0;
    for (std::size_t k = 0; k < pads.size(); ++k) {
      Grip g;
      g.pad = pads[k];
      g.share = share[k] / total;
      const auto uv = nominal_point(g.pad, e.grasp);
      g.u0 = uv[0];
      g.v0 = uv[1];
      g.psi = psi0 + rng_.uniform(-10.0, 10.0) * kDeg;
      const auto at = pads_.location(g.pad, g.u0, g.v0);
      g.lever_x = at[0];
      g.lever_y = at[1];
      cx += at[0];
      cy += at[1];
      e.grips.push_back(g);
    }
    cx /= static_cast<double>(e.grips.size());
    cy /= static_cast<double>(e.grips.size());
    for (Grip& g : e.grips) {
      g.lever_x -= cx;
      g.lever_y -= cy;
      const double len = std::hypot(g.lever_x, g.lever_y);
      if (len > kMaxLever) {
        g.lever_x *= kMaxLever / len;
        g.lever_y *= kMaxLever / len;
      }
    }
    // Forces.
    e.mu = o.friction;
    e.weight = o.weight(cfg_.gravity);
    const double s = rng_.uniform(cfg_.safety_min, cfg_.safety_max);
    e.grip = std::max(cfg_.grip_min, s * e.weight / e.mu);
    e.gravity_angle = rng_.uniform(0.0, 2.0 * std::numbers::pi);
    e.fluct_period = rng_.uniform(20.0, 80.0);
    e.fluct_phase = rng_.uniform(0.0, 2.0 * std::numbers::pi);
    e.x = rng_.uniform(-cfg_.start_offset_cm, cfg_.start_offset_cm);
    e.y = rng_.uniform(-cfg_.start_offset_cm, cfg_.start_offset_cm);
    e.theta = rng_.uniform(-cfg_.start_theta_deg, cfg_.start_theta_deg);

    // The episode's course.
    seg(GraspPhase::grasp, 0);  // length set when it starts (from the contacts' onsets)
    seg(GraspPhase::lift, range(cfg_.lift_frames_min, cfg_.lift_frames_max));
    const int actions = range(cfg_.actions_min, cfg_.actions_max);
    const bool can_regrasp = e.grips.size() >= 3;
    for (int a = 0; a < actions; ++a) {
      const int kind = can_regrasp ? static_cast<int>(rng_.below(4)) : 1 + static_cast<int>(rng_.below(3));
      Segment sg;
      switch (kind) {
        case 0: sg.phase = GraspPhase::regrasp; break;  // length set when it starts
        case 1:
          sg.phase = GraspPhase::rotate;
          sg.frames = range(cfg_.rotate_frames_min, cfg_.rotate_frames_max);
          sg.theta_to = rng_.uniform(-cfg_.max_theta_deg, cfg_.max_theta_deg);
          break;
        case 2:
          sg.phase = GraspPhase::slide;
          sg.frames = range(cfg_.slide_frames_min, cfg_.slide_frames_max);
          sg.x_to = rng_.uniform(-cfg_.max_offset_cm, cfg_.max_offset_cm);
          sg.y_to = rng_.uniform(-cfg_.max_offset_cm, cfg_.max_offset_cm);
          break;
        default:
          sg.phase = GraspPhase::hold;
          sg.frames = range(cfg_.hold_frames_min, cfg_.hold_frames_max);
      }
      e.segments.push_back(sg);
    }
    seg(GraspPhase::place, range(cfg_.place_frames_min, cfg_.place_frames_max));
    seg(GraspPhase::release, 0);  // length set when it starts
  }

  // Draws what a segment needs when it begins (contact timings), so that its length is known.
  void begin_segment(Segment& s) {
    Episode& e = ep_;
    e.x_from = e.x;
    e.y_from = e.y;
    e.theta_from = e.theta;
    int end = 0;
    switch (s.phase) {
      case GraspPhase::grasp:
      case GraspPhase::release:
        for (Grip& g : e.grips) {
          draw_onset(g);
          end = std::max(end, g.delay + g.up);
        }
        s.frames = end + (s.phase == GraspPhase::grasp ? 5 : 1);
        break;
      case GraspPhase::regrasp: {
        // 1 finger (2 with >= 5 contacts) other than the thumb lets go and comes back elsewhere.
        std::vector<int> candidates;
        for (int k = 0; k < static_cast<int>(e.grips.size()); ++k)
          if (e.grips[k].pad > kThumbTip + 2) candidates.push_back(k);
        rng_.shuffle(std::span<int>(candidates));
        const std::size_t n = std::min<std::size_t>(e.grips.size() >= 5 ? 2 : 1, candidates.size());
        for (std::size_t j = 0; j < n; ++j) {
          Grip& g = e.grips[static_cast<std::size_t>(candidates[j])];
          g.regrasping = true;
          g.delay = range(0, cfg_.onset_delay_max);
          g.down = range(cfg_.ramp_frames_min, cfg_.ramp_frames_max);
          g.off = range(cfg_.off_frames_min, cfg_.off_frames_max);
          g.up = range(cfg_.ramp_frames_min, cfg_.ramp_frames_max);
          const auto uv = nominal_point(g.pad, e.grasp);
          g.u_new = uv[0];
          g.v_new = uv[1];
          end = std::max(end, g.delay + g.down + g.off + g.up);
        }
        s.frames = end + 5;
        break;
      }
      default: break;
    }
  }

  // Contact pattern of object o on a pad (centre, pad and forces set by the caller).
  static ContactState object_contact(const GraspObject& o) {
    ContactState c;
    c.shape = o.shape;
    c.size = o.contact_size;
    c.edge_radius = o.edge_radius;
    c.points = o.points;
    return c;
  }

  // Advances one frame: fills the label's episode fields and contacts_.
  void step(GraspLabel& l) {
    Episode& e = ep_;
    while (e.seg >= e.segments.size() || e.k >= e.segments[e.seg].frames) {
      if (e.seg >= e.segments.size()) {
        start_episode();
      } else {
        ++e.seg;
        e.k = 0;
        if (e.seg >= e.segments.size()) continue;
      }
      begin_segment(e.segments[e.seg]);
    }
    const Segment& s = e.segments[e.seg];
    const int k = e.k++;
    ++e.frame;
    contacts_.clear();
    l.episode = e.id;
    l.episode_object = e.object;
    l.phase = static_cast<int>(s.phase);
    if (s.phase == GraspPhase::idle || s.phase == GraspPhase::reach) return;
    if (s.phase == GraspPhase::touch) {
      touch_frame(k);
      return;
    }
    const GraspObject& o = grasp_objects()[static_cast<std::size_t>(e.object)];
    l.object = e.object;
    l.grasp = static_cast<int>(e.grasp);
    l.held = s.phase != GraspPhase::grasp && s.phase != GraspPhase::place && s.phase != GraspPhase::release;

    // Pose: moves only in rotate and slide.
    const double ramp = detail::smoothstep((k + 1.0) / s.frames);
    if (s.phase == GraspPhase::rotate) e.theta = e.theta_from + ramp * (s.theta_to - e.theta_from);
    if (s.phase == GraspPhase::slide) {
      e.x = e.x_from + ramp * (s.x_to - e.x_from);
      e.y = e.y_from + ramp * (s.y_to - e.y_from);
    }
    l.x_cm = static_cast<float>(e.x);
    l.y_cm = static_cast<float>(e.y);
    l.theta_deg = static_cast<float>(e.theta);

    // Normal forces: the grasp and release ramp each contact on or off; otherwise the contacts on
    // the object share the grip (a re-grasping finger's part goes to the others).
    const double grip =
        e.grip * (1.0 + 0.05 * std::sin(2.0 * std::numbers::pi * e.frame / e.fluct_period + e.fluct_phase));
    double on_share = 0;
    for (Grip& g : e.grips) {
      if (s.phase == GraspPhase::regrasp && g.regrasping) {
        const int t = k - g.delay;
        if (t < 0) {
          g.activation = 1;
        } else if (t < g.down) {
          g.activation = 1.0 - detail::smoothstep((t + 1.0) / g.down);
        } else if (t < g.down + g.off) {
          g.activation = 0;
          g.u0 = g.u_new;  // re-placed while in the air
          g.v0 = g.v_new;
        } else {
          g.activation = detail::smoothstep((t - g.down - g.off + 1.0) / g.up);
        }
        if (k + 1 == s.frames) g.regrasping = false;
      } else if (s.phase == GraspPhase::grasp) {
        g.activation = detail::smoothstep((k - g.delay + 1.0) / g.up);
      } else if (s.phase == GraspPhase::release) {
        g.activation = 1.0 - detail::smoothstep((k - g.delay + 1.0) / g.up);
      } else {
        g.activation = 1;
      }
      on_share += g.share * g.activation;
    }
    const bool ramping = s.phase == GraspPhase::grasp || s.phase == GraspPhase::release;
    // Load fraction carried by the grip.
    double load = 0;
    if (s.phase == GraspPhase::lift) load = ramp;
    else if (s.phase == GraspPhase::place) load = 1.0 - ramp;
    else if (l.held) load = 1;
    const double th = e.theta * kDeg, co = std::cos(th), si = std::sin(th);
    const double dx = 10.0 * e.x, dy = 10.0 * e.y;  // mm
    const double gx = std::cos(e.gravity_angle), gy = std::sin(e.gravity_angle);
    // First pass: normal forces of the contacts that touch.
    double touching = 0;
    for (Grip& g : e.grips) {
      const double fn = on_share > 0 ? grip * g.share * g.activation / (ramping ? 1.0 : on_share) : 0.0;
      if (fn < cfg_.contact_threshold) {
        g.touching = false;
        g.shear_u = g.shear_v = 0;
        continue;
      }
      Contact c;
      c.state = object_contact(o);
      c.state.pad = g.pad;
      c.state.normal = fn;
      c.friction = e.mu;
      touching += fn;
      contacts_.push_back(c);
    }
    // Second pass: where, and the shear.
    std::size_t j = 0;
    for (Grip& g : e.grips) {
      if (j >= contacts_.size() || contacts_[j].state.pad != g.pad) continue;
      ContactState& c = contacts_[j++].state;
      const PadFrames::Pad& P = pads_[g.pad];
      // Hand-frame displacement of this contact: d + (R(θ) − I)·ℓ.
      const double hx = dx + (co - 1.0) * g.lever_x - si * g.lever_y;
      const double hy = dy + si * g.lever_x + (co - 1.0) * g.lever_y;
      c.u = std::clamp(g.u0 + hx * P.eu[0] + hy * P.eu[1], P.u_min, P.u_max);
      c.v = std::clamp(g.v0 + hx * P.ev[0] + hy * P.ev[1], P.v_min, P.v_max);
      c.orientation = g.psi + th;
      // Shear target: the load along gravity, shared in proportion to the normal force, plus a
      // traction along the contact's motion on the pad.
      const double w = load * e.weight * c.normal / touching;
      double tu = w * (gx * P.eu[0] + gy * P.eu[1]), tv = w * (gx * P.ev[0] + gy * P.ev[1]);
      if (g.touching) {
        const double mu_ = c.u - g.u_prev, mv = c.v - g.v_prev, len = std::hypot(mu_, mv);
        if (len > 1e-9) {
          tu += cfg_.motion_traction * e.mu * c.normal * mu_ / len;
          tv += cfg_.motion_traction * e.mu * c.normal * mv / len;
        }
      }
      detail::follow_traction(g.shear_u, g.shear_v, tu, tv, e.mu * c.normal);
      c.shear_u = g.shear_u;
      c.shear_v = g.shear_v;
      g.u_prev = c.u;
      g.v_prev = c.v;
      g.touching = true;
    }
  }

  // An incidental touch's frame k: press, hold, release.
  void touch_frame(int k) {
    Touch& t = ep_.touch;
    if (k == 0) t.shear_u = t.shear_v = 0;
    double fn;
    if (k < t.ramp) fn = t.peak * detail::smoothstep((k + 1.0) / t.ramp);
    else if (k < t.ramp + t.hold) fn = t.peak;
    else fn = t.peak * (1.0 - detail::smoothstep((k - t.ramp - t.hold + 1.0) / (t.release + 1.0)));
    detail::follow_traction(t.shear_u, t.shear_v, t.frac * fn * std::cos(t.dir), t.frac * fn * std::sin(t.dir),
                            cfg_.touch_friction * fn);
    if (fn < cfg_.contact_threshold) return;
    Contact c;
    c.state = t.shape;
    c.state.normal = fn;
    c.state.shear_u = t.shear_u;
    c.state.shear_v = t.shear_v;
    c.friction = cfg_.touch_friction;
    contacts_.push_back(c);
  }

  GraspSimConfig cfg_;
  Rng rng_;
  SkinGeometry geo_;
  PadFrames pads_;
  SkinSensor sensor_;
  std::array<std::array<double, 2>, layouts::allegro::kPads> finger_dir_{};  // [pad] layout unit vector
  Episode ep_;
  int episodes_ = 0;       // episodes started (reseed does not reset it: ids stay unique in a session)
  std::vector<int> deck_;  // objects left in this round, drawn from the back
  std::vector<Contact> contacts_;
};

}  // namespace tjepa

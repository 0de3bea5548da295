#pragma once
// SimulatedSkin: tjepa's built-in data. A physically plausible magnetic skin (like Xela uSkin: each
// taxel reads x, y shear and z normal) over any layout with coordinates, touched by indenters.
//
// Model, per contact event (one at a time by default, events following each other with free gaps;
// record(frames, contacts) lets several indenters touch at once, each with its own events):
//   * An indenter of one of four shapes lands on a random pad at a random point (a random taxel of
//     the pad, jittered by up to half the pad's pitch):
//       sphere       radius R ∈ [4, 15] mm: Hertz contact, radius a = (3·F·R / 4E*)^(1/3) grows with
//                    force; pressure variance a²/5 per axis (that of √(1 − r²/a²)).
//       flat         cylinder punch of radius R ∈ [3, 8] mm: contact radius R at any force, pressure
//                    concentrated at the rim (a centre lobe plus a ring of six lobes at 0.7·R).
//       edge         a ridge of half-length L ∈ [6, 15] mm at a random angle: five lobes along the
//                    line, line-contact half-width b = √(4·F'·1 mm / πE*), F' = F / 2L.
//       multi-point  three small spheres (R = 1.5 mm) at a radius s ∈ [5, 9] mm around the centre,
//                    each carrying F/3.
//     The pressure is a mixture of 2-D Gaussian lobes in the pad's plane, so the elastomer cover
//     (thickness h: a Gaussian blur of std h) is exact: each lobe's covariance grows by h²·I.
//   * Time course: press (smooth ramp to a peak normal force, log-uniform in [0.3, 10] N), hold
//     (±5 % slow fluctuation), with probability 0.6 a slide to another point of the pad, release.
//     Shear: while sticking, a static tangential push below the friction limit in a random
//     direction; while sliding, kinetic friction μ·F_n along the motion (μ ∈ [0.4, 1] per event);
//     the tangential force follows its target with a lag of a few frames and never exceeds μ·F_n.
//   * Taxel i (on the touched pad only) with blurred pressure density p_i (1/mm², integrates to 1):
//       z = S_z · F_n · p_i,   (x, y) = S_s · (F_t · p_i + β·h·F_n · g_i),
//     g_i = Σ w_k Σ'_k⁻¹ (x_i − c_k) N_k(x_i) the outward bulge of the cover (shear from the
//     pressure gradient, as magnetic taxels show), S in counts per kPa, then a soft saturation
//     S_max·tanh(·/S_max) and a per-taxel, per-axis gain 1 ± gain_spread.
//   * Sensor on top of the signal, every taxel and frame: a per-taxel offset (raw counts around
//     35000, as Xela reports), white noise (std noise_std counts; the sum of four uniform 16-bit
//     draws, Irwin–Hall, for speed), slow drift (Ornstein–Uhlenbeck, std drift_std, correlation
//     time drift_time), and drop-outs: a taxel reads exactly 0 on all axes for 1..dropout_frames_max
//     frames, starting at dropout_rate per taxel per frame (0 lies outside the valid Xela range, so
//     PreprocessConfig::xela_counts() treats it as a drop-out).
//
// Axes: x, y along the pad's plane (e_u, e_v), z along its normal (SimConfig::axes = 1 keeps only z,
// like a piezoresistive skin); the pad frame comes from a
// principal-component fit of the pad's taxel positions (e_u is the layout's x axis projected into
// the plane). Labels (FrameLabel): force (shear u, shear v, normal) in N in that frame, the contact
// centre in layout coordinates (mm), the indenter class and the pad.
//
// The rendering of a contact and the sensor (pad frames, pressure lobes, transduction, offsets,
// noise, drift, drop-outs) live in contact_model.hpp, shared with SimulatedHand (grasping_hand.hpp).
//
// Everything is drawn from one tjepa::Rng seeded at construction: the same geometry, config, seed
// and sequence of record() calls give the same data bit for bit.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/labels.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/layout/taxel_layout.hpp"
#include "tjepa/sim/contact_model.hpp"

namespace tjepa {

// The skin's physics (rate, axes, elastomer, transduction, sensor) come from SkinPhysics
// (contact_model.hpp); the fields here drive the contact events.
struct SimConfig : SkinPhysics {
  // Contact events.
  double force_min = 0.3, force_max = 10.0;  // N, peak normal force (log-uniform)
  double friction_min = 0.4, friction_max = 1.0;
  double slide_probability = 0.6;
  int gap_frames_min = 5, gap_frames_max = 60;  // free frames before each event
  int press_frames_min = 5, press_frames_max = 30;
  int hold_frames_min = 10, hold_frames_max = 60;
  int slide_frames_min = 20, slide_frames_max = 80;
  int release_frames_min = 3, release_frames_max = 20;
  void validate() const {
    auto pos = [](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v > 0, "SimConfig: ", name, " = ", v, ", expected > 0");
    };
    auto range = [](double lo, double hi, const char* name) {
      require<ConfigError>(lo <= hi, "SimConfig: ", name, " range [", lo, ", ", hi, "], expected min <= max");
    };
    validate_physics("SimConfig");
    pos(force_min, "force_min");
    range(force_min, force_max, "force");
    require<ConfigError>(std::isfinite(friction_min) && friction_min >= 0, "SimConfig: friction_min = ", friction_min,
                         ", expected >= 0");
    range(friction_min, friction_max, "friction");
    require<ConfigError>(slide_probability >= 0 && slide_probability <= 1, "SimConfig: slide_probability = ",
                         slide_probability, ", expected in [0, 1]");
    require<ConfigError>(gap_frames_min >= 0 && press_frames_min >= 1 && hold_frames_min >= 0 &&
                             slide_frames_min >= 1 && release_frames_min >= 1,
                         "SimConfig: phase lengths must be >= 1 frame (gap and hold >= 0)");
    range(gap_frames_min, gap_frames_max, "gap_frames");
    range(press_frames_min, press_frames_max, "press_frames");
    range(hold_frames_min, hold_frames_max, "hold_frames");
    range(slide_frames_min, slide_frames_max, "slide_frames");
    range(release_frames_min, release_frames_max, "release_frames");
  }
};

// A simulated recording [T, N, 3] with one label per frame.
struct SimRecording {
  Recording recording;
  std::vector<FrameLabel> labels;  // [T]
};

class SimulatedSkin {
 public:

  SimulatedSkin(SkinGeometry geometry, SimConfig config = {}, std::uint64_t seed = 0)
      : geo_(std::move(geometry)), cfg_(std::move(config)), rng_(seed) {
    cfg_.validate();
    geo_.validate("SimulatedSkin");
    pads_ = PadFrames(geo_);
    sensor_ = SkinSensor(cfg_, geo_.size(), rng_);  // per-sensor constants, drawn once
  }

  SimulatedSkin(const TaxelLayout& layout, SimConfig config = {}, std::uint64_t seed = 0)
      : SimulatedSkin(SkinGeometry::from_layout(layout), std::move(config), seed) {}

  // New random events (contacts, noise, drift steps, drop-outs) from `seed`, on the same sensor:
  // the per-taxel offsets, gains and the drift's current state are kept. A probe's labelled data
  // then come from the very sensor a model was pre-trained on (its baseline still applies).
  void reseed(std::uint64_t seed) { rng_ = Rng(seed, 0x72657365ull /* "rese" */); }

  const SkinGeometry& geometry() const { return geo_; }
  const SimConfig& config() const { return cfg_; }
  int taxels() const { return geo_.size(); }
  int axes() const { return cfg_.axes; }
  int num_pads() const { return pads_.size(); }
  // Per-taxel reading with no contact, no noise and no drift: [N, axes] counts.
  const std::vector<float>& offsets() const { return sensor_.offsets(); }
  // Taxel i's position in its pad's plane (mm).
  std::array<double, 2> taxel_uv(int i) const { return {pads_.u(i), pads_.v(i)}; }
  // Taxel ids of pad p (empty if no taxel has that id).
  const std::vector<int>& pad_taxels(int p) const { return pads_.at(p).taxels; }
  // Layout coordinates (mm) of point (u, v) in pad p's plane.
  std::array<double, 3> location(int pad, double u, double v) const { return pads_.location(pad, u, v); }

  // Noise-free signal of one contact: out [N, axes] counts, zero off the contacted pad (no offset,
  // drift, noise or drop-out). This is the physics the recordings are built on.
  void respond(const ContactState& c, std::span<float> out) const {
    require<ShapeError>(out.size() == static_cast<std::size_t>(taxels()) * axes(), "SimulatedSkin::respond: out has ",
                        out.size(), " values, expected taxels*axes = ", static_cast<std::size_t>(taxels()) * axes());
    require<ConfigError>(c.pad >= 0 && c.pad < num_pads() && !pads_[c.pad].taxels.empty(),
                         "SimulatedSkin::respond: pad ", c.pad, " has no taxels");
    require<ConfigError>(c.size > 0 && c.normal >= 0, "SimulatedSkin::respond: size ", c.size, " and normal force ",
                         c.normal, ", expected size > 0 and force >= 0");
    std::fill(out.begin(), out.end(), 0.0f);
    sensor_.add_contact(pads_, c, out.data());
  }

  // A recording of `frames` frames with contact events, and its labels. Successive calls continue
  // the same sensor (drift, drop-outs) with new events.
  // contacts > 1: up to that many indenters touch at once (a hand holding and manipulating: each
  // runs its own sequence of events and gaps, on a pad of its own choosing; the signals add). The
  // labels then describe the first indenter only, so such recordings are meant for unlabelled
  // pre-training. contacts = 1 gives the same data as before this option existed.
  SimRecording record(int frames, int contacts = 1) {
    require<ConfigError>(frames >= 0, "SimulatedSkin::record: frames = ", frames, ", expected >= 0");
    require<ConfigError>(contacts >= 1 && contacts <= 64, "SimulatedSkin::record: contacts = ", contacts,
                         ", expected in [1, 64]");
    if (static_cast<int>(channels_.size()) < contacts) channels_.resize(static_cast<std::size_t>(contacts));
    SimRecording out;
    out.recording = Recording(frames, taxels(), axes());
    out.recording.set_source(contacts == 1 ? "simulated skin" : "simulated skin, multi-contact");
    out.labels.resize(frames);
    float* x = out.recording.mutable_data();
    for (int t = 0; t < frames; ++t) {
      float* f = x + static_cast<std::size_t>(t) * taxels() * axes();
      sensor_.noise_frame(rng_, f);
      for (int k = 0; k < contacts; ++k) {
        ContactState c;
        if (!next_contact(channels_[static_cast<std::size_t>(k)], c)) continue;
        sensor_.add_contact(pads_, c, f);
        if (k > 0) continue;
        FrameLabel& l = out.labels[t];
        l.force = {static_cast<float>(c.shear_u), static_cast<float>(c.shear_v), static_cast<float>(c.normal)};
        const auto loc = location(c.pad, c.u, c.v);
        l.location = {static_cast<float>(loc[0]), static_cast<float>(loc[1]), static_cast<float>(loc[2])};
        l.indenter = static_cast<int>(c.shape);
        l.pad = c.pad;
      }
      sensor_.apply_dropouts(rng_, f);
    }
    return out;
  }

  // A contact-free recording of the same sensor (for fitting the preprocessing baseline).
  Recording record_baseline(int frames) {
    require<ConfigError>(frames >= 0, "SimulatedSkin::record_baseline: frames = ", frames, ", expected >= 0");
    return sensor_.record_baseline(rng_, frames, "simulated skin (no contact)");
  }

 private:
  // One contact event, drawn when the previous one ends.
  struct Event {
    IndenterShape shape;
    double size, orientation, peak, mu, fluct_period, fluct_phase;
    int pad;
    double u0, v0, u1, v1;        // start and end of the slide (equal if no slide)
    double static_frac, static_dir;
    int gap, press, hold, slide, release;
    int total() const { return gap + press + hold + slide + release; }
  };
  // One indenter: its current event, the frame within it and its lagging tangential force.
  struct Channel {
    std::optional<Event> event;
    int k = 0;
    double shear_u = 0, shear_v = 0;
  };

  int range(int lo, int hi) { return lo + static_cast<int>(rng_.below(static_cast<std::uint64_t>(hi - lo + 1))); }

  Event draw_event() {
    Event e;
    e.shape = static_cast<IndenterShape>(rng_.below(num_indenter_shapes));
    static constexpr double size_lo[] = {4.0, 3.0, 6.0, 5.0}, size_hi[] = {15.0, 8.0, 15.0, 9.0};
    const int s = static_cast<int>(e.shape);
    e.size = rng_.uniform(size_lo[s], size_hi[s]);
    e.orientation = rng_.uniform(0.0, std::numbers::pi);
    e.peak = std::exp(rng_.uniform(std::log(cfg_.force_min), std::log(cfg_.force_max)));
    e.mu = rng_.uniform(cfg_.friction_min, cfg_.friction_max);
    e.fluct_period = rng_.uniform(20.0, 80.0);
    e.fluct_phase = rng_.uniform(0.0, 2.0 * std::numbers::pi);
    e.pad = pads_.live_pads()[rng_.below(pads_.live_pads().size())];
    const PadFrames::Pad& P = pads_[e.pad];
    auto point = [&](double& u, double& v) {
      const int i = P.taxels[rng_.below(P.taxels.size())];
      u = pads_.u(i) + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
      v = pads_.v(i) + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
    };
    point(e.u0, e.v0);
    e.gap = range(cfg_.gap_frames_min, cfg_.gap_frames_max);
    e.press = range(cfg_.press_frames_min, cfg_.press_frames_max);
    e.hold = range(cfg_.hold_frames_min, cfg_.hold_frames_max);
    e.release = range(cfg_.release_frames_min, cfg_.release_frames_max);
    if (rng_.uniform() < cfg_.slide_probability && P.taxels.size() > 1) {
      point(e.u1, e.v1);
      e.slide = range(cfg_.slide_frames_min, cfg_.slide_frames_max);
    } else {
      e.u1 = e.u0;
      e.v1 = e.v0;
      e.slide = 0;
    }
    e.static_frac = rng_.uniform(0.0, 0.4) * e.mu;
    e.static_dir = rng_.uniform(0.0, 2.0 * std::numbers::pi);
    return e;
  }

  // Advances one indenter's event clock by one frame; true (and c filled) if it touches the skin.
  bool next_contact(Channel& ch, ContactState& c) {
    if (!ch.event || ch.k >= ch.event->total()) {
      ch.event = draw_event();
      ch.k = 0;
      ch.shear_u = ch.shear_v = 0;
    }
    const Event& e = *ch.event;
    const int k = ch.k++;
    double& su = ch.shear_u;
    double& sv = ch.shear_v;
    if (k < e.gap) return false;
    const int t = k - e.gap;
    double fn, pos = 0.0;
    bool sliding = false;
    if (t < e.press) {
      fn = e.peak * detail::smoothstep((t + 1.0) / e.press);
    } else if (t < e.press + e.hold) {
      fn = e.peak * (1.0 + 0.05 * std::sin(2.0 * std::numbers::pi * (t - e.press) / e.fluct_period + e.fluct_phase));
    } else if (t < e.press + e.hold + e.slide) {
      const int ts = t - e.press - e.hold;
      fn = e.peak * (1.0 + 0.05 * std::sin(2.0 * std::numbers::pi * (t - e.press) / e.fluct_period + e.fluct_phase));
      pos = detail::smoothstep((ts + 1.0) / e.slide);
      sliding = true;
    } else {
      const int tr = t - e.press - e.hold - e.slide;
      const double last = e.peak * (1.0 + 0.05 * std::sin(2.0 * std::numbers::pi * (e.hold + e.slide) / e.fluct_period + e.fluct_phase));
      fn = last * (1.0 - detail::smoothstep((tr + 1.0) / (e.release + 1.0)));
      pos = e.slide > 0 ? 1.0 : 0.0;
    }
    // Tangential force: static push while sticking, kinetic friction along the motion while sliding.
    double tu = e.static_frac * fn * std::cos(e.static_dir), tv = e.static_frac * fn * std::sin(e.static_dir);
    if (sliding) {
      const double du = e.u1 - e.u0, dv = e.v1 - e.v0, len = std::hypot(du, dv);
      if (len > 1e-9) {
        tu = e.mu * fn * du / len;
        tv = e.mu * fn * dv / len;
      }
    }
    detail::follow_traction(su, sv, tu, tv, e.mu * fn);
    c.shape = e.shape;
    c.size = e.size;
    c.pad = e.pad;
    c.orientation = e.orientation;
    c.u = e.u0 + pos * (e.u1 - e.u0);
    c.v = e.v0 + pos * (e.v1 - e.v0);
    c.normal = fn;
    c.shear_u = su;
    c.shear_v = sv;
    return true;
  }

  SkinGeometry geo_;
  SimConfig cfg_;
  Rng rng_;
  PadFrames pads_;
  SkinSensor sensor_;
  std::vector<Channel> channels_ = std::vector<Channel>(1);  // one per simultaneous indenter
};

}  // namespace tjepa

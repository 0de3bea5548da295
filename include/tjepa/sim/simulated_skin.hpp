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
//     PreprocessConfig::magnetic() treats it as a drop-out).
//
// Axes: x, y along the pad's plane (e_u, e_v), z along its normal (SimConfig::axes = 1 keeps only z,
// like a piezoresistive skin); the pad frame comes from a
// principal-component fit of the pad's taxel positions (e_u is the layout's x axis projected into
// the plane). Labels (FrameLabel): force (shear u, shear v, normal) in N in that frame, the contact
// centre in layout coordinates (mm), the indenter class and the pad.
//
// Everything is drawn from one tjepa::Rng seeded at construction: the same geometry, config, seed
// and sequence of record() calls give the same data bit for bit.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/detail/vendor.hpp"
#include <Eigen/Eigenvalues>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/labels.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

// What the simulator needs from a layout: taxel positions (mm) and each taxel's pad.
struct SkinGeometry {
  std::vector<std::array<double, 3>> position;  // [N] mm (z = 0 for a flat 2-D layout)
  std::vector<int> pad;                         // [N] pad (group) id in [0, P)

  int size() const { return static_cast<int>(position.size()); }
  int num_pads() const { return pad.empty() ? 0 : *std::max_element(pad.begin(), pad.end()) + 1; }

  // From a layout with 2-D or 3-D coordinates; the pads are its groups.
  static SkinGeometry from_layout(const TaxelLayout& layout) {
    layout.validate();
    require<ConfigError>(layout.has_coords(), "SkinGeometry::from_layout: the layout has no coordinates; the "
                                              "simulated skin needs taxel positions (dim 2 or 3)");
    SkinGeometry g;
    g.position.resize(static_cast<std::size_t>(layout.size()));
    for (int i = 0; i < layout.size(); ++i)
      for (int a = 0; a < 3; ++a) g.position[i][a] = layout.coord(i, a);
    g.pad = layout.group;
    return g;
  }
};

enum class IndenterShape : int { sphere = 0, flat = 1, edge = 2, multi_point = 3 };
inline constexpr int num_indenter_shapes = 4;
inline const char* indenter_name(int shape) {
  static const char* names[] = {"sphere", "flat", "edge", "multi-point"};
  return shape >= 0 && shape < num_indenter_shapes ? names[shape] : "none";
}

// One instant of one contact, in the pad's frame.
struct ContactState {
  IndenterShape shape = IndenterShape::sphere;
  double size = 6.0;         // mm: radius (sphere, flat), half-length (edge), spread (multi-point)
  int pad = 0;
  double u = 0.0, v = 0.0;   // mm, contact centre in the pad's plane
  double orientation = 0.0;  // rad, edge and multi-point
  double shear_u = 0.0, shear_v = 0.0, normal = 0.0;  // N
};

struct SimConfig {
  double rate_hz = 100.0;
  int axes = 3;  // 3: magnetic (x, y shear, z normal); 1: pressure only (piezoresistive), the z reading
  // Contact events.
  double force_min = 0.3, force_max = 10.0;  // N, peak normal force (log-uniform)
  double friction_min = 0.4, friction_max = 1.0;
  double slide_probability = 0.6;
  int gap_frames_min = 5, gap_frames_max = 60;  // free frames before each event
  int press_frames_min = 5, press_frames_max = 30;
  int hold_frames_min = 10, hold_frames_max = 60;
  int slide_frames_min = 20, slide_frames_max = 80;
  int release_frames_min = 3, release_frames_max = 20;
  // Elastomer and transduction.
  double modulus = 0.25;            // N/mm², effective contact modulus E*
  double cover_thickness = 1.5;     // mm, h
  double bulge = 0.5;               // β
  double normal_sensitivity = 30.0; // counts per kPa
  double shear_sensitivity = 20.0;  // counts per kPa
  double saturation = 20000.0;      // counts
  double gain_spread = 0.1;
  // Sensor.
  bool raw_counts = true;           // add per-taxel offsets (Xela-like raw counts); false: signal around 0
  double offset_mean = 35000.0, offset_spread = 4000.0;  // counts
  double noise_std = 10.0;          // counts
  double drift_std = 30.0;          // counts
  double drift_time = 30.0;         // s
  double dropout_rate = 2e-4;       // per taxel per frame
  int dropout_frames_max = 10;

  void validate() const {
    auto pos = [](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v > 0, "SimConfig: ", name, " = ", v, ", expected > 0");
    };
    auto nonneg = [](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v >= 0, "SimConfig: ", name, " = ", v, ", expected >= 0");
    };
    auto range = [](double lo, double hi, const char* name) {
      require<ConfigError>(lo <= hi, "SimConfig: ", name, " range [", lo, ", ", hi, "], expected min <= max");
    };
    pos(rate_hz, "rate_hz");
    require<ConfigError>(axes == 1 || axes == 3, "SimConfig: axes = ", axes, ", expected 3 (x, y, z) or 1 (pressure)");
    pos(force_min, "force_min");
    range(force_min, force_max, "force");
    nonneg(friction_min, "friction_min");
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
    pos(modulus, "modulus");
    pos(cover_thickness, "cover_thickness");
    nonneg(bulge, "bulge");
    pos(normal_sensitivity, "normal_sensitivity");
    nonneg(shear_sensitivity, "shear_sensitivity");
    pos(saturation, "saturation");
    require<ConfigError>(gain_spread >= 0 && gain_spread < 1, "SimConfig: gain_spread = ", gain_spread,
                         ", expected in [0, 1)");
    nonneg(offset_mean, "offset_mean");
    nonneg(offset_spread, "offset_spread");
    nonneg(noise_std, "noise_std");
    nonneg(drift_std, "drift_std");
    pos(drift_time, "drift_time");
    require<ConfigError>(dropout_rate >= 0 && dropout_rate < 1, "SimConfig: dropout_rate = ", dropout_rate,
                         ", expected in [0, 1)");
    require<ConfigError>(dropout_frames_max >= 1, "SimConfig: dropout_frames_max = ", dropout_frames_max,
                         ", expected >= 1");
  }
};

// A simulated recording [T, N, 3] with one label per frame.
struct SimRecording {
  Recording recording;
  std::vector<FrameLabel> labels;  // [T]
};

namespace detail {

// N(0, 1) approximated by the Irwin–Hall sum of four 16-bit uniforms from one 64-bit draw
// (support ±3.46σ): one engine call instead of Box–Muller's log, sqrt and cos.
inline float fast_normal(Rng& rng) {
  const std::uint64_t r = rng();
  const auto s = static_cast<float>((r & 0xffff) + ((r >> 16) & 0xffff) + ((r >> 32) & 0xffff) + (r >> 48));
  return (s - 131070.0f) * (1.0f / 37837.23f);
}

inline double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace detail

class SimulatedSkin {
 public:

  SimulatedSkin(SkinGeometry geometry, SimConfig config = {}, std::uint64_t seed = 0)
      : geo_(std::move(geometry)), cfg_(std::move(config)), rng_(seed) {
    cfg_.validate();
    const int n = geo_.size();
    require<DataError>(n > 0, "SimulatedSkin: the geometry has no taxels");
    require<ShapeError>(static_cast<int>(geo_.pad.size()) == n, "SimulatedSkin: ", geo_.pad.size(),
                        " pad ids for ", n, " taxels");
    for (int i = 0; i < n; ++i) {
      require<DataError>(geo_.pad[i] >= 0, "SimulatedSkin: taxel ", i, " has pad ", geo_.pad[i], ", expected >= 0");
      for (int a = 0; a < 3; ++a)
        require<DataError>(std::isfinite(geo_.position[i][a]), "SimulatedSkin: taxel ", i,
                           " has a non-finite coordinate ", geo_.position[i][a]);
    }
    build_pads();
    // Per-sensor constants, drawn once.
    gain_.resize(static_cast<std::size_t>(n) * cfg_.axes);
    offset_.resize(gain_.size());
    drift_.resize(gain_.size());
    for (auto& g : gain_) g = static_cast<float>(1.0 + cfg_.gain_spread * rng_.uniform(-1.0, 1.0));
    for (auto& o : offset_)
      o = cfg_.raw_counts ? static_cast<float>(cfg_.offset_mean + cfg_.offset_spread * rng_.uniform(-1.0, 1.0)) : 0.0f;
    for (auto& d : drift_) d = static_cast<float>(cfg_.drift_std * rng_.normal());
    dropout_left_.assign(n, 0);
    next_dropout_ = draw_dropout_gap();
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
  int num_pads() const { return static_cast<int>(pads_.size()); }
  // Per-taxel reading with no contact, no noise and no drift: [N, axes] counts.
  const std::vector<float>& offsets() const { return offset_; }
  // Taxel i's position in its pad's plane (mm).
  std::array<double, 2> taxel_uv(int i) const { return {uv_[2 * i], uv_[2 * i + 1]}; }
  // Taxel ids of pad p (empty if no taxel has that id).
  const std::vector<int>& pad_taxels(int p) const { return pads_.at(p).taxels; }
  // Layout coordinates (mm) of point (u, v) in pad p's plane.
  std::array<double, 3> location(int pad, double u, double v) const {
    const Pad& P = pads_.at(pad);
    std::array<double, 3> x{};
    for (int a = 0; a < 3; ++a) x[a] = P.origin[a] + u * P.eu[a] + v * P.ev[a];
    return x;
  }

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
    add_signal(c, out.data());
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
      sensor_frame(f);
      for (int k = 0; k < contacts; ++k) {
        ContactState c;
        if (!next_contact(channels_[static_cast<std::size_t>(k)], c)) continue;
        add_signal(c, f);
        if (k > 0) continue;
        FrameLabel& l = out.labels[t];
        l.force = {static_cast<float>(c.shear_u), static_cast<float>(c.shear_v), static_cast<float>(c.normal)};
        const auto loc = location(c.pad, c.u, c.v);
        l.location = {static_cast<float>(loc[0]), static_cast<float>(loc[1]), static_cast<float>(loc[2])};
        l.indenter = static_cast<int>(c.shape);
        l.pad = c.pad;
      }
      apply_dropouts(f);
    }
    return out;
  }

  // A contact-free recording of the same sensor (for fitting the preprocessing baseline).
  Recording record_baseline(int frames) {
    require<ConfigError>(frames >= 0, "SimulatedSkin::record_baseline: frames = ", frames, ", expected >= 0");
    Recording rec(frames, taxels(), axes());
    rec.set_source("simulated skin (no contact)");
    float* x = rec.mutable_data();
    for (int t = 0; t < frames; ++t) {
      float* f = x + static_cast<std::size_t>(t) * taxels() * axes();
      sensor_frame(f);
      apply_dropouts(f);
    }
    return rec;
  }

 private:
  struct Pad {
    std::vector<int> taxels;
    std::array<double, 3> origin{}, eu{}, ev{}, en{};
    double pitch = 1.0;  // mean nearest-neighbour distance, mm
  };
  struct Lobe {
    double cu, cv, w;       // centre (mm), weight (sums to 1)
    double s00, s01, s11;   // covariance (mm²), before the cover's blur
  };
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

  void build_pads() {
    const int P = geo_.num_pads();
    pads_.assign(P, {});
    for (int i = 0; i < geo_.size(); ++i) pads_[geo_.pad[i]].taxels.push_back(i);
    uv_.assign(2 * static_cast<std::size_t>(geo_.size()), 0.0);
    for (int p = 0; p < P; ++p) {
      Pad& pad = pads_[p];
      if (pad.taxels.empty()) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int i : pad.taxels) mean += Eigen::Vector3d(geo_.position[i][0], geo_.position[i][1], geo_.position[i][2]);
      mean /= static_cast<double>(pad.taxels.size());
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (int i : pad.taxels) {
        const Eigen::Vector3d d = Eigen::Vector3d(geo_.position[i][0], geo_.position[i][1], geo_.position[i][2]) - mean;
        cov += d * d.transpose();
      }
      Eigen::Vector3d n(0, 0, 1);
      if (pad.taxels.size() >= 3) {
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
        n = es.eigenvectors().col(0);  // smallest variance: the pad's normal
        // A flat pad has a zero smallest eigenvalue with a unique normal; if the taxels are collinear or
        // the fit is ambiguous, keep the layout's z.
        if (es.eigenvalues()(1) <= 1e-9 * std::max(1.0, es.eigenvalues()(2))) n = Eigen::Vector3d(0, 0, 1);
      }
      if (n.z() < 0 || (n.z() == 0 && n.x() < 0)) n = -n;
      Eigen::Vector3d u = Eigen::Vector3d::UnitX() - n.x() * n;
      if (u.norm() < 0.3) u = Eigen::Vector3d::UnitY() - n.y() * n;
      u.normalize();
      const Eigen::Vector3d v = n.cross(u);
      for (int a = 0; a < 3; ++a) {
        pad.origin[a] = mean(a);
        pad.eu[a] = u(a);
        pad.ev[a] = v(a);
        pad.en[a] = n(a);
      }
      for (int i : pad.taxels) {
        const Eigen::Vector3d d = Eigen::Vector3d(geo_.position[i][0], geo_.position[i][1], geo_.position[i][2]) - mean;
        uv_[2 * i] = d.dot(u);
        uv_[2 * i + 1] = d.dot(v);
      }
      double sum = 0;
      int cnt = 0;
      for (int i : pad.taxels) {
        double best = 1e300;
        for (int j : pad.taxels)
          if (j != i) best = std::min(best, std::hypot(uv_[2 * i] - uv_[2 * j], uv_[2 * i + 1] - uv_[2 * j + 1]));
        if (best < 1e300) {
          sum += best;
          ++cnt;
        }
      }
      pad.pitch = cnt > 0 && sum > 0 ? sum / cnt : 4.0;
    }
    for (int p = 0; p < P; ++p)
      if (!pads_[p].taxels.empty()) live_pads_.push_back(p);
  }

  // The indenter's pressure as Gaussian lobes (weights sum to 1), before the cover's blur.
  int lobes(const ContactState& c, Lobe* out) const {
    const double F = std::max(c.normal, 1e-9), E = cfg_.modulus;
    const double co = std::cos(c.orientation), si = std::sin(c.orientation);
    auto iso = [](double cu, double cv, double w, double var) { return Lobe{cu, cv, w, var, 0.0, var}; };
    switch (c.shape) {
      case IndenterShape::sphere: {
        const double a = std::cbrt(3.0 * F * c.size / (4.0 * E));
        out[0] = iso(c.u, c.v, 1.0, a * a / 5.0);
        return 1;
      }
      case IndenterShape::flat: {
        const double R = c.size;
        out[0] = iso(c.u, c.v, 0.25, 0.1225 * R * R);
        for (int k = 0; k < 6; ++k) {
          const double ang = c.orientation + k * std::numbers::pi / 3.0;
          out[1 + k] = iso(c.u + 0.7 * R * std::cos(ang), c.v + 0.7 * R * std::sin(ang), 0.125, 0.09 * R * R);
        }
        return 7;
      }
      case IndenterShape::edge: {
        const double L = c.size;
        const double b2 = 4.0 * (F / (2.0 * L)) * 1.0 / (std::numbers::pi * E);  // half-width squared
        const double along = 0.0625 * L * L, across = b2 / 4.0;
        // R diag(along, across) Rᵀ with R the rotation by the orientation.
        const double s00 = co * co * along + si * si * across, s11 = si * si * along + co * co * across;
        const double s01 = co * si * (along - across);
        for (int k = 0; k < 5; ++k) {
          const double t = (-0.8 + 0.4 * k) * L;
          out[k] = Lobe{c.u + t * co, c.v + t * si, 0.2, s00, s01, s11};
        }
        return 5;
      }
      case IndenterShape::multi_point: {
        const double a = std::cbrt(3.0 * (F / 3.0) * 1.5 / (4.0 * E));
        for (int k = 0; k < 3; ++k) {
          const double ang = c.orientation + k * 2.0 * std::numbers::pi / 3.0;
          out[k] = iso(c.u + c.size * std::cos(ang), c.v + c.size * std::sin(ang), 1.0 / 3.0, a * a / 5.0);
        }
        return 3;
      }
    }
    return 0;
  }

  // Adds the contact's signal (counts) to frame f [N, 3].
  void add_signal(const ContactState& c, float* f) const {
    Lobe lb[8];
    const int nl = lobes(c, lb);
    const double h2 = cfg_.cover_thickness * cfg_.cover_thickness;
    // Blurred covariance inverse and normalisation per lobe.
    double i00[8], i01[8], i11[8], norm[8];
    for (int k = 0; k < nl; ++k) {
      const double a = lb[k].s00 + h2, b = lb[k].s01, d = lb[k].s11 + h2;
      const double det = a * d - b * b;
      i00[k] = d / det;
      i01[k] = -b / det;
      i11[k] = a / det;
      norm[k] = lb[k].w / (2.0 * std::numbers::pi * std::sqrt(det));
    }
    const double kpa = 1000.0;  // N/mm² -> kPa
    const double Smax = cfg_.saturation;
    const double bulge = cfg_.bulge * cfg_.cover_thickness;
    for (int i : pads_[c.pad].taxels) {
      const double xu = uv_[2 * i], xv = uv_[2 * i + 1];
      double p = 0, gu = 0, gv = 0;
      for (int k = 0; k < nl; ++k) {
        const double du = xu - lb[k].cu, dv = xv - lb[k].cv;
        const double q = du * (i00[k] * du + i01[k] * dv) + dv * (i01[k] * du + i11[k] * dv);
        if (q > 60.0) continue;  // e^-30: nothing
        const double nk = norm[k] * std::exp(-0.5 * q);
        p += nk;
        gu += nk * (i00[k] * du + i01[k] * dv);
        gv += nk * (i01[k] * du + i11[k] * dv);
      }
      if (p == 0.0) continue;
      const double sx = cfg_.shear_sensitivity * kpa * (c.shear_u * p + bulge * c.normal * gu);
      const double sy = cfg_.shear_sensitivity * kpa * (c.shear_v * p + bulge * c.normal * gv);
      const double sz = cfg_.normal_sensitivity * kpa * c.normal * p;
      const int m = cfg_.axes;
      float* fi = f + static_cast<std::size_t>(i) * m;
      const float* g = gain_.data() + static_cast<std::size_t>(i) * m;
      fi[m - 1] += g[m - 1] * static_cast<float>(Smax * std::tanh(sz / Smax));
      if (m == 3) {
        fi[0] += g[0] * static_cast<float>(Smax * std::tanh(sx / Smax));
        fi[1] += g[1] * static_cast<float>(Smax * std::tanh(sy / Smax));
      }
    }
  }

  // Offsets, drift and noise for every taxel: f [N, 3].
  void sensor_frame(float* f) {
    const std::size_t n = gain_.size();
    const float noise = static_cast<float>(cfg_.noise_std);
    // The drift is slow (seconds) against the frame rate: one Ornstein–Uhlenbeck step per
    // drift_stride frames is indistinguishable and halves the random draws.
    if (cfg_.drift_std > 0 && frame_++ % drift_stride == 0) {
      const double rho = std::exp(-static_cast<double>(drift_stride) / (cfg_.drift_time * cfg_.rate_hz));
      const auto r = static_cast<float>(rho);
      const auto s = static_cast<float>(cfg_.drift_std * std::sqrt(1.0 - rho * rho));
      for (std::size_t k = 0; k < n; ++k) drift_[k] = r * drift_[k] + s * detail::fast_normal(rng_);
    }
    for (std::size_t k = 0; k < n; ++k) f[k] = offset_[k] + drift_[k] + noise * detail::fast_normal(rng_);
  }

  // Geometric gap (in taxel-frames) to the next drop-out start.
  std::int64_t draw_dropout_gap() {
    if (cfg_.dropout_rate <= 0) return INT64_MAX;
    const double u = 1.0 - rng_.uniform();  // (0, 1]
    const double g = std::floor(std::log(u) / std::log1p(-cfg_.dropout_rate));
    return g > 1e15 ? INT64_MAX : static_cast<std::int64_t>(g);
  }

  void apply_dropouts(float* f) {
    const int n = taxels();
    // New drop-outs starting in this frame.
    std::int64_t pos = 0;
    while (next_dropout_ < n - pos) {
      pos += next_dropout_;
      dropout_left_[pos] = std::max(dropout_left_[pos], 1 + static_cast<int>(rng_.below(cfg_.dropout_frames_max)));
      ++pos;
      next_dropout_ = draw_dropout_gap();
    }
    if (next_dropout_ != INT64_MAX) next_dropout_ -= n - pos;
    for (int i = 0; i < n; ++i)
      if (dropout_left_[i] > 0) {
        --dropout_left_[i];
        std::fill_n(f + static_cast<std::size_t>(i) * cfg_.axes, cfg_.axes, 0.0f);
      }
  }

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
    e.pad = live_pads_[rng_.below(live_pads_.size())];
    const Pad& P = pads_[e.pad];
    auto point = [&](double& u, double& v) {
      const int i = P.taxels[rng_.below(P.taxels.size())];
      u = uv_[2 * i] + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
      v = uv_[2 * i + 1] + 0.5 * P.pitch * rng_.uniform(-1.0, 1.0);
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
    su += 0.3 * (tu - su);
    sv += 0.3 * (tv - sv);
    const double mag = std::hypot(su, sv), limit = e.mu * fn;
    if (mag > limit) {
      su *= limit / mag;
      sv *= limit / mag;
    }
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
  std::vector<Pad> pads_;
  std::vector<int> live_pads_;
  std::vector<double> uv_;       // [N, 2]
  std::vector<float> gain_;      // [N, 3]
  std::vector<float> offset_;    // [N, 3]
  std::vector<float> drift_;     // [N, 3]
  static constexpr int drift_stride = 8;
  std::int64_t frame_ = 0;       // frames generated so far
  std::vector<int> dropout_left_;  // [N] frames of drop-out left
  std::int64_t next_dropout_ = 0;  // taxel-frames until the next drop-out starts
  std::vector<Channel> channels_ = std::vector<Channel>(1);  // one per simultaneous indenter
};

}  // namespace tjepa

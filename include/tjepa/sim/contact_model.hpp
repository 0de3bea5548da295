#pragma once
// The simulated skin's response model, shared by SimulatedSkin (one indenter) and SimulatedHand (a
// hand grasping objects): what one contact does to a magnetic skin's taxels, and the sensor's own
// offsets, noise, drift and drop-outs. The physics is described in simulated_skin.hpp's header
// comment; the pieces here are:
//   SkinGeometry  taxel positions (mm) and pads, from a layout with coordinates
//   PadFrames     each pad's plane (origin, e_u, e_v, normal), its taxels' (u, v) and pitch
//   ContactState  one contact at one instant, in its pad's frame
//   SkinPhysics   elastomer, transduction and sensor parameters (SimConfig's defaults)
//   SkinSensor    per-taxel gains, offsets, drift and drop-out state; renders contacts into counts
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

#include "tjepa/core/detail/vendor.hpp"
#include <Eigen/Eigenvalues>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
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

  // Throws unless every taxel has a pad id >= 0 and finite coordinates; `who` names the caller.
  void validate(const char* who) const {
    const int n = size();
    require<DataError>(n > 0, who, ": the geometry has no taxels");
    require<ShapeError>(static_cast<int>(pad.size()) == n, who, ": ", pad.size(), " pad ids for ", n, " taxels");
    for (int i = 0; i < n; ++i) {
      require<DataError>(pad[i] >= 0, who, ": taxel ", i, " has pad ", pad[i], ", expected >= 0");
      for (int a = 0; a < 3; ++a)
        require<DataError>(std::isfinite(position[i][a]), who, ": taxel ", i, " has a non-finite coordinate ",
                           position[i][a]);
    }
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
  double edge_radius = 1.0;  // mm, radius of an edge's ridge (a cylinder lying on the pad)
  int points = 3;            // multi-point: small spheres on the circle of radius `size`
};

// The skin itself: elastomer, transduction and sensor. SimConfig and GraspSimConfig extend it.
struct SkinPhysics {
  double rate_hz = 100.0;
  int axes = 3;  // 3: magnetic (x, y shear, z normal); 1: pressure only (piezoresistive), the z reading
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

  // Throws ConfigError naming `who` (the config's type) and the field.
  void validate_physics(const char* who) const {
    auto pos = [who](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v > 0, who, ": ", name, " = ", v, ", expected > 0");
    };
    auto nonneg = [who](double v, const char* name) {
      require<ConfigError>(std::isfinite(v) && v >= 0, who, ": ", name, " = ", v, ", expected >= 0");
    };
    pos(rate_hz, "rate_hz");
    require<ConfigError>(axes == 1 || axes == 3, who, ": axes = ", axes, ", expected 3 (x, y, z) or 1 (pressure)");
    pos(modulus, "modulus");
    pos(cover_thickness, "cover_thickness");
    nonneg(bulge, "bulge");
    pos(normal_sensitivity, "normal_sensitivity");
    nonneg(shear_sensitivity, "shear_sensitivity");
    pos(saturation, "saturation");
    require<ConfigError>(gain_spread >= 0 && gain_spread < 1, who, ": gain_spread = ", gain_spread,
                         ", expected in [0, 1)");
    nonneg(offset_mean, "offset_mean");
    nonneg(offset_spread, "offset_spread");
    nonneg(noise_std, "noise_std");
    nonneg(drift_std, "drift_std");
    pos(drift_time, "drift_time");
    require<ConfigError>(dropout_rate >= 0 && dropout_rate < 1, who, ": dropout_rate = ", dropout_rate,
                         ", expected in [0, 1)");
    require<ConfigError>(dropout_frames_max >= 1, who, ": dropout_frames_max = ", dropout_frames_max,
                         ", expected >= 1");
  }
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

// A contact's tangential force (su, sv) (N) follows its target (tu, tv) with a lag of a few frames
// (30 % of the way per frame) and never exceeds the friction limit μ·F_n (N).
inline void follow_traction(double& su, double& sv, double tu, double tv, double limit) {
  su += 0.3 * (tu - su);
  sv += 0.3 * (tv - sv);
  const double mag = std::hypot(su, sv);
  if (mag > limit) {
    su *= limit / mag;
    sv *= limit / mag;
  }
}

}  // namespace detail

// Each pad's plane from a principal-component fit of its taxel positions: e_n the direction of
// least variance (the layout's z if the pad is collinear or ambiguous), e_u the layout's x axis
// projected into the plane, e_v = e_n × e_u.
class PadFrames {
 public:
  struct Pad {
    std::vector<int> taxels;
    std::array<double, 3> origin{}, eu{}, ev{}, en{};  // mm, unit vectors
    double pitch = 1.0;  // mean nearest-neighbour distance, mm
    double u_min = 0, u_max = 0, v_min = 0, v_max = 0;  // mm, the rectangle spanned by the taxels
  };

  PadFrames() = default;
  explicit PadFrames(const SkinGeometry& geo) {
    const int P = geo.num_pads();
    pads_.assign(P, {});
    for (int i = 0; i < geo.size(); ++i) pads_[geo.pad[i]].taxels.push_back(i);
    uv_.assign(2 * static_cast<std::size_t>(geo.size()), 0.0);
    auto at = [&](int i) { return Eigen::Vector3d(geo.position[i][0], geo.position[i][1], geo.position[i][2]); };
    for (int p = 0; p < P; ++p) {
      Pad& pad = pads_[p];
      if (pad.taxels.empty()) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int i : pad.taxels) mean += at(i);
      mean /= static_cast<double>(pad.taxels.size());
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (int i : pad.taxels) {
        const Eigen::Vector3d d = at(i) - mean;
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
      pad.u_min = pad.v_min = 1e300;
      pad.u_max = pad.v_max = -1e300;
      for (int i : pad.taxels) {
        const Eigen::Vector3d d = at(i) - mean;
        uv_[2 * i] = d.dot(u);
        uv_[2 * i + 1] = d.dot(v);
        pad.u_min = std::min(pad.u_min, uv_[2 * i]);
        pad.u_max = std::max(pad.u_max, uv_[2 * i]);
        pad.v_min = std::min(pad.v_min, uv_[2 * i + 1]);
        pad.v_max = std::max(pad.v_max, uv_[2 * i + 1]);
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

  int size() const { return static_cast<int>(pads_.size()); }
  const Pad& operator[](int p) const { return pads_[p]; }
  const Pad& at(int p) const { return pads_.at(p); }
  // Pads with at least one taxel, ascending.
  const std::vector<int>& live_pads() const { return live_pads_; }
  // Taxel i's position in its pad's plane (mm).
  double u(int i) const { return uv_[2 * i]; }
  double v(int i) const { return uv_[2 * i + 1]; }
  // Layout coordinates (mm) of point (u, v) in pad p's plane.
  std::array<double, 3> location(int pad, double u, double v) const {
    const Pad& P = pads_.at(pad);
    std::array<double, 3> x{};
    for (int a = 0; a < 3; ++a) x[a] = P.origin[a] + u * P.eu[a] + v * P.ev[a];
    return x;
  }

 private:
  std::vector<Pad> pads_;
  std::vector<int> live_pads_;
  std::vector<double> uv_;  // [N, 2] mm
};

// A 2-D Gaussian pressure lobe in a pad's plane.
struct PressureLobe {
  double cu, cv, w;       // centre (mm), weight (sums to 1)
  double s00, s01, s11;   // covariance (mm²), before the cover's blur
};
inline constexpr int max_pressure_lobes = 16;

// The contact's pressure as Gaussian lobes (weights sum to 1), before the cover's blur; returns the
// count (at most max_pressure_lobes). E: the contact modulus (N/mm²).
inline int pressure_lobes(const ContactState& c, double E, PressureLobe* out) {
  const double F = std::max(c.normal, 1e-9);
  const double co = std::cos(c.orientation), si = std::sin(c.orientation);
  auto iso = [](double cu, double cv, double w, double var) { return PressureLobe{cu, cv, w, var, 0.0, var}; };
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
      const double b2 = 4.0 * (F / (2.0 * L)) * c.edge_radius / (std::numbers::pi * E);  // half-width squared
      const double along = 0.0625 * L * L, across = b2 / 4.0;
      // R diag(along, across) Rᵀ with R the rotation by the orientation.
      const double s00 = co * co * along + si * si * across, s11 = si * si * along + co * co * across;
      const double s01 = co * si * (along - across);
      for (int k = 0; k < 5; ++k) {
        const double t = (-0.8 + 0.4 * k) * L;
        out[k] = PressureLobe{c.u + t * co, c.v + t * si, 0.2, s00, s01, s11};
      }
      return 5;
    }
    case IndenterShape::multi_point: {
      const int n = std::clamp(c.points, 1, max_pressure_lobes);
      const double a = std::cbrt(3.0 * (F / static_cast<double>(n)) * 1.5 / (4.0 * E));
      for (int k = 0; k < n; ++k) {
        const double ang = c.orientation + k * 2.0 * std::numbers::pi / static_cast<double>(n);
        out[k] = iso(c.u + c.size * std::cos(ang), c.v + c.size * std::sin(ang), 1.0 / static_cast<double>(n),
                     a * a / 5.0);
      }
      return n;
    }
  }
  return 0;
}

// The sensor: per-taxel, per-axis gains and raw-count offsets, the drift's state and the drop-outs
// in progress. Random draws come from the caller's Rng, so a simulator keeps one stream.
class SkinSensor {
 public:
  SkinSensor() = default;
  // Draws the gains, offsets and the drift's initial state for `taxels` taxels from rng.
  SkinSensor(const SkinPhysics& physics, int taxels, Rng& rng) : phys_(physics), taxels_(taxels) {
    gain_.resize(static_cast<std::size_t>(taxels) * phys_.axes);
    offset_.resize(gain_.size());
    drift_.resize(gain_.size());
    for (auto& g : gain_) g = static_cast<float>(1.0 + phys_.gain_spread * rng.uniform(-1.0, 1.0));
    for (auto& o : offset_)
      o = phys_.raw_counts ? static_cast<float>(phys_.offset_mean + phys_.offset_spread * rng.uniform(-1.0, 1.0))
                           : 0.0f;
    for (auto& d : drift_) d = static_cast<float>(phys_.drift_std * rng.normal());
    dropout_left_.assign(taxels, 0);
    next_dropout_ = draw_dropout_gap(rng);
  }

  int taxels() const { return taxels_; }
  int axes() const { return phys_.axes; }
  // Per-taxel reading with no contact, no noise and no drift: [N, axes] counts.
  const std::vector<float>& offsets() const { return offset_; }

  // Adds contact c's signal (counts) to frame f [N, axes]: only c's pad changes.
  //   z = S_z · F_n · p_i,   (x, y) = S_s · (F_t · p_i + β·h·F_n · g_i),
  // p_i the cover-blurred pressure density at taxel i (1/mm²), g_i the cover's outward bulge; then
  // the soft saturation S_max·tanh(·/S_max) and the taxel's gain.
  void add_contact(const PadFrames& pads, const ContactState& c, float* f) const {
    PressureLobe lb[max_pressure_lobes];
    const int nl = pressure_lobes(c, phys_.modulus, lb);
    const double h2 = phys_.cover_thickness * phys_.cover_thickness;
    // Blurred covariance inverse and normalisation per lobe.
    double i00[max_pressure_lobes], i01[max_pressure_lobes], i11[max_pressure_lobes], norm[max_pressure_lobes];
    for (int k = 0; k < nl; ++k) {
      const double a = lb[k].s00 + h2, b = lb[k].s01, d = lb[k].s11 + h2;
      const double det = a * d - b * b;
      i00[k] = d / det;
      i01[k] = -b / det;
      i11[k] = a / det;
      norm[k] = lb[k].w / (2.0 * std::numbers::pi * std::sqrt(det));
    }
    const double kpa = 1000.0;  // N/mm² -> kPa
    const double Smax = phys_.saturation;
    const double bulge = phys_.bulge * phys_.cover_thickness;
    for (int i : pads[c.pad].taxels) {
      const double xu = pads.u(i), xv = pads.v(i);
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
      const double sx = phys_.shear_sensitivity * kpa * (c.shear_u * p + bulge * c.normal * gu);
      const double sy = phys_.shear_sensitivity * kpa * (c.shear_v * p + bulge * c.normal * gv);
      const double sz = phys_.normal_sensitivity * kpa * c.normal * p;
      const int m = phys_.axes;
      float* fi = f + static_cast<std::size_t>(i) * m;
      const float* g = gain_.data() + static_cast<std::size_t>(i) * m;
      fi[m - 1] += g[m - 1] * static_cast<float>(Smax * std::tanh(sz / Smax));
      if (m == 3) {
        fi[0] += g[0] * static_cast<float>(Smax * std::tanh(sx / Smax));
        fi[1] += g[1] * static_cast<float>(Smax * std::tanh(sy / Smax));
      }
    }
  }

  // Writes offsets, drift and white noise for every taxel into f [N, axes] (one frame).
  void noise_frame(Rng& rng, float* f) {
    const std::size_t n = gain_.size();
    const float noise = static_cast<float>(phys_.noise_std);
    // The drift is slow (seconds) against the frame rate: one Ornstein–Uhlenbeck step per
    // drift_stride frames is indistinguishable and halves the random draws.
    if (phys_.drift_std > 0 && frame_++ % drift_stride == 0) {
      const double rho = std::exp(-static_cast<double>(drift_stride) / (phys_.drift_time * phys_.rate_hz));
      const auto r = static_cast<float>(rho);
      const auto s = static_cast<float>(phys_.drift_std * std::sqrt(1.0 - rho * rho));
      for (std::size_t k = 0; k < n; ++k) drift_[k] = r * drift_[k] + s * detail::fast_normal(rng);
    }
    for (std::size_t k = 0; k < n; ++k) f[k] = offset_[k] + drift_[k] + noise * detail::fast_normal(rng);
  }

  // `frames` contact-free frames of this sensor [frames, N, axes] (for the preprocessing baseline).
  Recording record_baseline(Rng& rng, int frames, std::string source) {
    Recording rec(frames, taxels_, axes());
    rec.set_source(std::move(source));
    float* x = rec.mutable_data();
    for (int t = 0; t < frames; ++t) {
      float* f = x + static_cast<std::size_t>(t) * taxels_ * axes();
      noise_frame(rng, f);
      apply_dropouts(rng, f);
    }
    return rec;
  }

  // Starts new drop-outs and zeroes every taxel in one (all axes) in frame f [N, axes]. 0 lies
  // outside the valid Xela range, so PreprocessConfig::xela_counts() treats it as a drop-out.
  void apply_dropouts(Rng& rng, float* f) {
    const int n = taxels_;
    // New drop-outs starting in this frame.
    std::int64_t pos = 0;
    while (next_dropout_ < n - pos) {
      pos += next_dropout_;
      dropout_left_[pos] = std::max(dropout_left_[pos], 1 + static_cast<int>(rng.below(phys_.dropout_frames_max)));
      ++pos;
      next_dropout_ = draw_dropout_gap(rng);
    }
    if (next_dropout_ != INT64_MAX) next_dropout_ -= n - pos;
    for (int i = 0; i < n; ++i)
      if (dropout_left_[i] > 0) {
        --dropout_left_[i];
        std::fill_n(f + static_cast<std::size_t>(i) * phys_.axes, phys_.axes, 0.0f);
      }
  }

 private:
  // Geometric gap (in taxel-frames) to the next drop-out start.
  std::int64_t draw_dropout_gap(Rng& rng) const {
    if (phys_.dropout_rate <= 0) return INT64_MAX;
    const double u = 1.0 - rng.uniform();  // (0, 1]
    const double g = std::floor(std::log(u) / std::log1p(-phys_.dropout_rate));
    return g > 1e15 ? INT64_MAX : static_cast<std::int64_t>(g);
  }

  SkinPhysics phys_;
  int taxels_ = 0;
  std::vector<float> gain_;        // [N, axes]
  std::vector<float> offset_;      // [N, axes] counts
  std::vector<float> drift_;       // [N, axes] counts
  static constexpr int drift_stride = 8;
  std::int64_t frame_ = 0;         // frames generated so far
  std::vector<int> dropout_left_;  // [N] frames of drop-out left
  std::int64_t next_dropout_ = 0;  // taxel-frames until the next drop-out starts
};

}  // namespace tjepa

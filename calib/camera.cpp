#include "calib/camera.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <sstream>

namespace omni {
namespace {

// A bearing whose depth is below this fraction of its length cannot be imaged by a perspective
// model (pinhole, opencv): it is behind the camera or at the horizon.
constexpr double kMinRelativeDepth = 1e-12;
// Below this ratio of |(x, y)| to |bearing| the fisheye uses the limit of its formulas at the
// optical axis (exact to far below double precision).
constexpr double kFisheyeAxisEpsilon = 1e-12;
// Iterative undistortion (Unproject).
constexpr int kMaxUndistortIterations = 100;
// Convergence of the undistortion, in normalised image coordinates (relative to the size of the
// distorted point when it is larger than 1).
constexpr double kUndistortTolerance = 1e-12;
// Backtracking steps of the line search of the 2-D Newton undistortion.
constexpr int kMaxLineSearchSteps = 60;
// A pixel whose unprojected bearing re-projects farther than this from it is rejected.
constexpr double kMaxReprojectionErrorPx = 1e-6;
// |‖q‖ − 1| above this makes cam_from_rig invalid.
constexpr double kUnitQuaternionTolerance = 1e-6;

constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Small real polynomials (degree <= 4), coefficients in increasing powers. Used to decide where a
// distortion's radial map stops increasing, exactly rather than by sampling.

struct Poly {
  std::array<double, 5> c{};
  int degree = 0;

  double operator()(double x) const {
    double v = c[degree];
    for (int i = degree - 1; i >= 0; --i) v = v * x + c[i];
    return v;
  }
  Poly Derivative() const {
    Poly d;
    d.degree = std::max(degree - 1, 0);
    for (int i = 1; i <= degree; ++i) d.c[i - 1] = i * c[i];
    if (degree == 0) d.c[0] = 0.0;
    return d;
  }
  // Drops exactly-zero leading coefficients.
  Poly Trimmed() const {
    Poly p = *this;
    while (p.degree > 0 && p.c[p.degree] == 0.0) --p.degree;
    return p;
  }
};

struct Roots {
  std::array<double, 4> x{};
  int count = 0;
  void Add(double r) {
    if (count > 0 && x[count - 1] == r) return;
    x[count++] = r;
  }
};

// The root of a polynomial that is monotone on [a, b] and changes sign there.
double BisectMonotone(const Poly& p, double a, double b) {
  double fa = p(a);
  for (int i = 0; i < 200; ++i) {
    const double m = 0.5 * (a + b);
    if (m <= a || m >= b) break;
    const double fm = p(m);
    if (fm == 0.0) return m;
    if ((fm < 0.0) == (fa < 0.0)) {
      a = m;
      fa = fm;
    } else {
      b = m;
    }
  }
  return 0.5 * (a + b);
}

// Real roots of p in [lo, hi], sorted: the roots of p' split [lo, hi] into intervals where p is
// monotone, each holding at most one root.
Roots RealRootsIn(const Poly& poly, double lo, double hi) {
  const Poly p = poly.Trimmed();
  Roots roots;
  if (p.degree == 0) return roots;
  if (p.degree == 1) {
    const double r = -p.c[0] / p.c[1];
    if (r >= lo && r <= hi) roots.Add(r);
    return roots;
  }
  const Roots critical = RealRootsIn(p.Derivative(), lo, hi);
  std::array<double, 6> breaks{};
  int num_breaks = 0;
  breaks[num_breaks++] = lo;
  for (int i = 0; i < critical.count; ++i)
    if (critical.x[i] > lo && critical.x[i] < hi) breaks[num_breaks++] = critical.x[i];
  breaks[num_breaks++] = hi;
  for (int i = 0; i + 1 < num_breaks; ++i) {
    const double a = breaks[i], b = breaks[i + 1];
    const double fa = p(a), fb = p(b);
    if (fa == 0.0) {
      roots.Add(a);
    } else if (fb != 0.0 && (fa < 0.0) != (fb < 0.0)) {
      roots.Add(BisectMonotone(p, a, b));
    }
  }
  if (p(hi) == 0.0) roots.Add(hi);
  return roots;
}

// A lower bound of p on [0, t_max] (t_max >= 0): its constant term plus its negative terms at
// t_max.
double LowerBoundOn(const Poly& p, double t_max) {
  double bound = p.c[0];
  double power = 1.0;
  for (int i = 1; i <= p.degree; ++i) {
    power *= t_max;
    if (p.c[i] < 0.0) bound += p.c[i] * power;
  }
  return bound;
}

// Whether p > 0 on all of [0, t_max].
bool PositiveOn(const Poly& p, double t_max) {
  if (LowerBoundOn(p, t_max) > 0.0) return true;
  if (!(p(0.0) > 0.0) || !(p(t_max) > 0.0)) return false;
  const Roots critical = RealRootsIn(p.Derivative(), 0.0, t_max);
  for (int i = 0; i < critical.count; ++i)
    if (!(p(critical.x[i]) > 0.0)) return false;
  return true;
}

// ---------------------------------------------------------------------------------------------
// OpenCV (Brown-Conrady) distortion of normalised coordinates (x, y) = (X/Z, Y/Z):
//   r² = x² + y², radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
//   xd = x radial + 2 p1 x y + p2 (r² + 2 x²)
//   yd = y radial + p1 (r² + 2 y²) + 2 p2 x y

struct OpenCVDistortion {
  double k1, k2, p1, p2, k3;

  explicit OpenCVDistortion(const std::vector<double>& params)
      : k1(params[4]), k2(params[5]), p1(params[6]), p2(params[7]), k3(params[8]) {}

  Eigen::Vector2d Apply(const Eigen::Vector2d& u, Eigen::Matrix2d* jacobian) const {
    const double x = u.x(), y = u.y();
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const Eigen::Vector2d d(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y);
    if (jacobian) {
      // d radial / d r² .
      const double dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
      (*jacobian)(0, 0) = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x;
      (*jacobian)(0, 1) = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
      (*jacobian)(1, 0) = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
      (*jacobian)(1, 1) = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x;
    }
    return d;
  }

  // d(r radial(r)) / dr = 1 + 3 k1 r² + 5 k2 r⁴ + 7 k3 r⁶ as a polynomial in s = r².
  Poly RadialSlope() const {
    Poly p;
    p.c = {1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3, 0.0};
    p.degree = 3;
    return p;
  }

  // One-to-one at u: the radial map increases on [0, r] and the 2x2 Jacobian keeps its
  // orientation.
  bool IsValid(const Eigen::Vector2d& u, const Eigen::Matrix2d& jacobian) const {
    if (!u.allFinite()) return false;
    if (!(jacobian.determinant() > 0.0)) return false;
    return PositiveOn(RadialSlope(), u.squaredNorm());
  }
  bool IsValid(const Eigen::Vector2d& u) const {
    Eigen::Matrix2d jacobian;
    Apply(u, &jacobian);
    return IsValid(u, jacobian);
  }
};

// ---------------------------------------------------------------------------------------------
// Fisheye (Kannala-Brandt as cv::fisheye): θ = atan2(|(X, Y)|, Z),
//   θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), (xd, yd) = θd (X, Y) / |(X, Y)|.

struct FisheyeDistortion {
  double k1, k2, k3, k4;

  explicit FisheyeDistortion(const std::vector<double>& params)
      : k1(params[4]), k2(params[5]), k3(params[6]), k4(params[7]) {}

  double ThetaD(double theta, double* dtheta_d) const {
    const double t2 = theta * theta;
    const double poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
    if (dtheta_d) *dtheta_d = Slope()(t2);
    return theta * poly;
  }
  // dθd/dθ = 1 + 3 k1 θ² + 5 k2 θ⁴ + 7 k3 θ⁶ + 9 k4 θ⁸ as a polynomial in t = θ².
  Poly Slope() const {
    Poly p;
    p.c = {1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3, 9.0 * k4};
    p.degree = 4;
    return p;
  }
  // The end of the range [0, θmax) where θd increases, capped at π.
  double MaxTheta() const {
    if (LowerBoundOn(Slope(), kPi * kPi) > 0.0) return kPi;
    const Roots roots = RealRootsIn(Slope(), 0.0, kPi * kPi);
    return roots.count > 0 ? std::sqrt(roots.x[0]) : kPi;
  }
  bool IsValid(double theta) const {
    return theta >= 0.0 && theta < kPi && PositiveOn(Slope(), theta * theta);
  }
};

bool HasParams(const Camera& camera) {
  return static_cast<int>(camera.params.size()) == NumCameraParams(camera.model);
}

bool ProjectPinholeLike(const Camera& camera, const Eigen::Vector3d& bearing,
                        Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* d_pixel_d_bearing) {
  const double z = bearing.z();
  if (!(z > kMinRelativeDepth * bearing.norm())) return false;
  const Eigen::Vector2d u(bearing.x() / z, bearing.y() / z);
  Eigen::Vector2d d = u;
  Eigen::Matrix2d d_d_u = Eigen::Matrix2d::Identity();
  if (camera.model == CameraModel::kOpenCV) {
    const OpenCVDistortion distortion(camera.params);
    d = distortion.Apply(u, &d_d_u);
    if (!distortion.IsValid(u, d_d_u)) return false;
  }
  *pixel = Eigen::Vector2d(camera.fx() * d.x() + camera.cx(), camera.fy() * d.y() + camera.cy());
  if (d_pixel_d_bearing) {
    Eigen::Matrix<double, 2, 3> d_u_d_bearing;
    d_u_d_bearing << 1.0 / z, 0.0, -u.x() / z, 0.0, 1.0 / z, -u.y() / z;
    *d_pixel_d_bearing =
        Eigen::Vector2d(camera.fx(), camera.fy()).asDiagonal() * d_d_u * d_u_d_bearing;
  }
  return true;
}

bool ProjectFisheye(const Camera& camera, const Eigen::Vector3d& bearing, Eigen::Vector2d* pixel,
                    Eigen::Matrix<double, 2, 3>* d_pixel_d_bearing) {
  const FisheyeDistortion distortion(camera.params);
  const double x = bearing.x(), y = bearing.y(), z = bearing.z();
  const double r2 = x * x + y * y;
  const double r = std::sqrt(r2);
  const double rho2 = r2 + z * z;
  if (!(rho2 > 0.0) || !std::isfinite(rho2)) return false;
  const double theta = std::atan2(r, z);
  if (!distortion.IsValid(theta)) return false;
  double slope = 0.0;
  const double theta_d = distortion.ThetaD(theta, &slope);
  // (xd, yd) = s (x, y) with s = θd / r.
  double s = 0.0;
  double c = 0.0;  // ds/dx = c x, ds/dy = c y.
  if (r > kFisheyeAxisEpsilon * std::sqrt(rho2)) {
    s = theta_d / r;
    c = (slope * z / rho2 - s) / r2;
  } else {
    // On the axis (θ = 0, z > 0): s = 1/z and the terms of c vanish with x and y.
    s = 1.0 / z;
  }
  const double fx = camera.fx(), fy = camera.fy();
  *pixel = Eigen::Vector2d(fx * s * x + camera.cx(), fy * s * y + camera.cy());
  if (d_pixel_d_bearing) {
    // ds/dz = θd' dθ/dz / r = -θd' / ρ².
    const double dsdz = -slope / rho2;
    Eigen::Matrix<double, 2, 3> j;
    j << s + c * x * x, c * x * y, dsdz * x, c * x * y, s + c * y * y, dsdz * y;
    j.row(0) *= fx;
    j.row(1) *= fy;
    *d_pixel_d_bearing = j;
  }
  return true;
}

// Solves distort(u) = target by Newton with backtracking on |distort(u) - target|, keeping every
// iterate where the distortion is one-to-one.
bool UndistortOpenCV(const OpenCVDistortion& distortion, const Eigen::Vector2d& target,
                     Eigen::Vector2d* undistorted) {
  const double tolerance = kUndistortTolerance * std::max(1.0, target.norm());
  Eigen::Vector2d u = target;
  for (int i = 0; i < kMaxLineSearchSteps && !distortion.IsValid(u); ++i) u *= 0.5;
  if (!distortion.IsValid(u)) return false;
  Eigen::Matrix2d jacobian;
  Eigen::Vector2d residual = distortion.Apply(u, &jacobian) - target;
  double residual_norm = residual.norm();
  for (int iteration = 0; iteration < kMaxUndistortIterations; ++iteration) {
    if (residual_norm <= tolerance) break;
    const Eigen::Vector2d step = -jacobian.partialPivLu().solve(residual);
    if (!step.allFinite()) return false;
    double alpha = 1.0;
    bool accepted = false;
    for (int k = 0; k < kMaxLineSearchSteps; ++k, alpha *= 0.5) {
      const Eigen::Vector2d trial = u + alpha * step;
      if (trial == u) break;
      Eigen::Matrix2d trial_jacobian;
      const Eigen::Vector2d trial_residual = distortion.Apply(trial, &trial_jacobian) - target;
      const double trial_norm = trial_residual.norm();
      if (trial_norm < residual_norm && distortion.IsValid(trial, trial_jacobian)) {
        u = trial;
        jacobian = trial_jacobian;
        residual = trial_residual;
        residual_norm = trial_norm;
        accepted = true;
        break;
      }
    }
    if (!accepted) break;
  }
  if (!(residual_norm <= tolerance)) return false;
  *undistorted = u;
  return true;
}

// Solves θd(θ) = target for θ in [0, θmax) by Newton safeguarded by bisection (θd increases
// there, so the root is unique).
bool UndistortFisheye(const FisheyeDistortion& distortion, double target, double* theta_out) {
  const double theta_max = distortion.MaxTheta();
  if (!(target < distortion.ThetaD(theta_max, nullptr))) return false;
  double lo = 0.0, hi = theta_max;
  double theta = std::min(target, 0.5 * (lo + hi));
  const double tolerance = kUndistortTolerance * std::max(1.0, target);
  for (int iteration = 0; iteration < kMaxUndistortIterations; ++iteration) {
    double slope = 0.0;
    const double f = distortion.ThetaD(theta, &slope) - target;
    if (std::abs(f) <= tolerance) {
      *theta_out = theta;
      return true;
    }
    if (f < 0.0) {
      lo = theta;
    } else {
      hi = theta;
    }
    double next = slope > 0.0 ? theta - f / slope : lo - 1.0;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (next == theta) break;
    theta = next;
  }
  return false;
}

}  // namespace

std::string_view CameraModelName(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return "pinhole";
    case CameraModel::kOpenCV:
      return "opencv";
    case CameraModel::kFisheye:
      return "fisheye";
  }
  return "unknown";
}

std::optional<CameraModel> CameraModelFromName(std::string_view name) {
  for (CameraModel model : {CameraModel::kPinhole, CameraModel::kOpenCV, CameraModel::kFisheye})
    if (CameraModelName(model) == name) return model;
  return std::nullopt;
}

int NumCameraParams(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return 4;
    case CameraModel::kOpenCV:
      return 9;
    case CameraModel::kFisheye:
      return 8;
  }
  return 0;
}

std::string_view CameraParamsDescription(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return "fx fy cx cy";
    case CameraModel::kOpenCV:
      return "fx fy cx cy k1 k2 p1 p2 k3";
    case CameraModel::kFisheye:
      return "fx fy cx cy k1 k2 k3 k4";
  }
  return "";
}

bool Camera::Project(const Eigen::Vector3d& bearing, Eigen::Vector2d* pixel,
                     Eigen::Matrix<double, 2, 3>* d_pixel_d_bearing) const {
  assert(pixel != nullptr);
  if (!HasParams(*this) || !bearing.allFinite()) return false;
  switch (model) {
    case CameraModel::kPinhole:
    case CameraModel::kOpenCV:
      return ProjectPinholeLike(*this, bearing, pixel, d_pixel_d_bearing);
    case CameraModel::kFisheye:
      return ProjectFisheye(*this, bearing, pixel, d_pixel_d_bearing);
  }
  return false;
}

bool Camera::Unproject(const Eigen::Vector2d& pixel, Eigen::Vector3d* bearing) const {
  assert(bearing != nullptr);
  if (!HasParams(*this) || !pixel.allFinite()) return false;
  const Eigen::Vector2d distorted((pixel.x() - cx()) / fx(), (pixel.y() - cy()) / fy());
  if (!distorted.allFinite()) return false;
  Eigen::Vector3d result;
  switch (model) {
    case CameraModel::kPinhole:
      result = distorted.homogeneous().normalized();
      break;
    case CameraModel::kOpenCV: {
      Eigen::Vector2d undistorted;
      if (!UndistortOpenCV(OpenCVDistortion(params), distorted, &undistorted)) return false;
      result = undistorted.homogeneous().normalized();
      break;
    }
    case CameraModel::kFisheye: {
      const double theta_d = distorted.norm();
      double theta = 0.0;
      if (theta_d > 0.0 && !UndistortFisheye(FisheyeDistortion(params), theta_d, &theta))
        return false;
      const double sin_over = theta_d > 0.0 ? std::sin(theta) / theta_d : 0.0;
      result = Eigen::Vector3d(sin_over * distorted.x(), sin_over * distorted.y(), std::cos(theta));
      break;
    }
  }
  Eigen::Vector2d reprojected;
  if (!Project(result, &reprojected)) return false;
  if (!((reprojected - pixel).norm() <= kMaxReprojectionErrorPx)) return false;
  *bearing = result;
  return true;
}

std::string Camera::Check() const {
  std::ostringstream problems;
  auto add = [&problems](const std::string& problem) {
    if (problems.tellp() > 0) problems << "; ";
    problems << problem;
  };
  if (name.empty()) add("name: empty");
  if (width <= 0) add("width: must be > 0, got " + std::to_string(width));
  if (height <= 0) add("height: must be > 0, got " + std::to_string(height));
  const int expected = NumCameraParams(model);
  if (static_cast<int>(params.size()) != expected) {
    add("params: expected " + std::to_string(expected) + " values (" +
        std::string(CameraParamsDescription(model)) + "), got " + std::to_string(params.size()));
  } else {
    bool finite = true;
    for (size_t i = 0; i < params.size(); ++i) {
      if (!std::isfinite(params[i])) {
        add("params[" + std::to_string(i) + "]: not finite");
        finite = false;
      }
    }
    if (finite) {
      std::ostringstream value;
      if (!(fx() > 0.0)) {
        value << "params[0] (fx): must be > 0, got " << fx();
        add(value.str());
      }
      if (!(fy() > 0.0)) {
        value.str("");
        value << "params[1] (fy): must be > 0, got " << fy();
        add(value.str());
      }
    }
  }
  const double norm = cam_from_rig.rotation.norm();
  if (!std::isfinite(norm) || !(std::abs(norm - 1.0) <= kUnitQuaternionTolerance)) {
    std::ostringstream value;
    value << "cam_from_rig.q_wxyz: not a unit quaternion (norm " << norm << ")";
    add(value.str());
  }
  if (!cam_from_rig.translation.allFinite()) add("cam_from_rig.t: not finite");
  return problems.str();
}

}  // namespace omni

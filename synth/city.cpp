#include "synth/city.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "synth/hash.h"

namespace omni::synth {
namespace {

using Eigen::Vector3d;

class MeshBuilder {
 public:
  explicit MeshBuilder(CityScene* scene) : scene_(scene) {}

  uint32_t NewObject() { return next_object_++; }

  void AddTriangle(const Vector3d& a, const Vector3d& b, const Vector3d& c, Surface surface,
                   uint32_t object) {
    const int base = static_cast<int>(scene_->mesh.vertices.size());
    scene_->mesh.vertices.push_back(a);
    scene_->mesh.vertices.push_back(b);
    scene_->mesh.vertices.push_back(c);
    scene_->mesh.triangles.emplace_back(base, base + 1, base + 2);
    scene_->surfaces.push_back(surface);
    scene_->objects.push_back(object);
  }

  // A planar quad p0 p1 p2 p3 (in order around it), oriented so that it faces `normal`.
  void AddQuad(const Vector3d& p0, const Vector3d& p1, const Vector3d& p2, const Vector3d& p3,
               const Vector3d& normal, Surface surface, uint32_t object) {
    const int base = static_cast<int>(scene_->mesh.vertices.size());
    for (const Vector3d& p : {p0, p1, p2, p3}) scene_->mesh.vertices.push_back(p);
    if ((p1 - p0).cross(p2 - p0).dot(normal) >= 0) {
      scene_->mesh.triangles.emplace_back(base, base + 1, base + 2);
      scene_->mesh.triangles.emplace_back(base, base + 2, base + 3);
    } else {
      scene_->mesh.triangles.emplace_back(base, base + 2, base + 1);
      scene_->mesh.triangles.emplace_back(base, base + 3, base + 2);
    }
    for (int i = 0; i < 2; ++i) {
      scene_->surfaces.push_back(surface);
      scene_->objects.push_back(object);
    }
  }

  // Axis-aligned box; faces whose outward normal is in `skip` (as +-x, +-y, +-z: index
  // 2*axis + (positive ? 1 : 0)) are left out.
  void AddBox(const Vector3d& lo, const Vector3d& hi, Surface surface, uint32_t object,
              std::array<bool, 6> skip = {}) {
    for (int axis = 0; axis < 3; ++axis) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int positive = 0; positive < 2; ++positive) {
        if (skip[2 * axis + positive]) continue;
        Vector3d normal = Vector3d::Zero();
        normal[axis] = positive ? 1.0 : -1.0;
        std::array<Vector3d, 4> corners;
        for (int k = 0; k < 4; ++k) {
          Vector3d p;
          p[axis] = positive ? hi[axis] : lo[axis];
          p[u] = (k == 1 || k == 2) ? hi[u] : lo[u];
          p[v] = (k >= 2) ? hi[v] : lo[v];
          corners[k] = p;
        }
        AddQuad(corners[0], corners[1], corners[2], corners[3], normal, surface, object);
      }
    }
  }

 private:
  CityScene* scene_;
  uint32_t next_object_ = 1;  // 0: the ground
};

// A facade seen from the street: u along it (to the right), v up, `out` towards the street.
struct FacadeFrame {
  Vector3d origin;  // bottom-left corner on the facade plane
  Vector3d along;   // unit, horizontal
  Vector3d normal;  // unit, outward, horizontal
  Vector3d At(double u, double v, double out = 0.0) const {
    return origin + u * along + v * Vector3d::UnitZ() + out * normal;
  }
};

struct Opening {
  double u0, u1, v0, v1;
  Surface back;
};

class FacadeMaker {
 public:
  FacadeMaker(const SynthCityOptions& options, MeshBuilder* builder, SplitMix* rng, uint32_t object)
      : options_(options), builder_(builder), rng_(rng), object_(object) {}

  void WallQuad(const FacadeFrame& f, double u0, double u1, double v0, double v1, double out,
                const Vector3d& normal, Surface surface) {
    if (u1 - u0 < 1e-6 || v1 - v0 < 1e-6) return;
    builder_->AddQuad(f.At(u0, v0, out), f.At(u1, v0, out), f.At(u1, v1, out), f.At(u0, v1, out),
                      normal, surface, object_);
  }

  // A box in facade coordinates, out in [out0, out1]; the face against the wall is left out
  // when out0 == 0.
  void FacadeBox(const FacadeFrame& f, double u0, double u1, double v0, double v1, double out0,
                 double out1, Surface surface) {
    const Vector3d a = f.At(u0, v0, out0), b = f.At(u1, v1, out1);
    std::array<bool, 6> skip{};
    if (out0 == 0.0) {
      for (int axis = 0; axis < 2; ++axis) {
        if (std::abs(f.normal[axis]) > 0.5) skip[2 * axis + (f.normal[axis] < 0 ? 1 : 0)] = true;
      }
    }
    builder_->AddBox(a.cwiseMin(b), a.cwiseMax(b), surface, object_, skip);
  }

  void Recess(const FacadeFrame& f, const Opening& o) {
    const double d = -options_.window_depth;
    const Vector3d& n = f.normal;
    const Vector3d z = Vector3d::UnitZ();
    WallQuad(f, o.u0, o.u1, o.v0, o.v1, d, n, o.back);
    builder_->AddQuad(f.At(o.u0, o.v0, 0), f.At(o.u1, o.v0, 0), f.At(o.u1, o.v0, d),
                      f.At(o.u0, o.v0, d), z, Surface::kReveal, object_);
    builder_->AddQuad(f.At(o.u0, o.v1, 0), f.At(o.u1, o.v1, 0), f.At(o.u1, o.v1, d),
                      f.At(o.u0, o.v1, d), -z, Surface::kReveal, object_);
    builder_->AddQuad(f.At(o.u0, o.v0, 0), f.At(o.u0, o.v1, 0), f.At(o.u0, o.v1, d),
                      f.At(o.u0, o.v0, d), f.along, Surface::kReveal, object_);
    builder_->AddQuad(f.At(o.u1, o.v0, 0), f.At(o.u1, o.v1, 0), f.At(o.u1, o.v1, d),
                      f.At(o.u1, o.v0, d), -f.along, Surface::kReveal, object_);
  }

  // One storey [va, vb] with its openings (sorted by u, inside the storey).
  void Row(const FacadeFrame& f, double width, double va, double vb,
           const std::vector<Opening>& openings) {
    double cursor = 0.0;
    for (const Opening& o : openings) {
      WallQuad(f, cursor, o.u0, va, vb, 0, f.normal, Surface::kWall);
      WallQuad(f, o.u0, o.u1, va, o.v0, 0, f.normal, Surface::kWall);
      WallQuad(f, o.u0, o.u1, o.v1, vb, 0, f.normal, Surface::kWall);
      Recess(f, o);
      cursor = o.u1;
    }
    WallQuad(f, cursor, width, va, vb, 0, f.normal, Surface::kWall);
  }

  void Facade(const FacadeFrame& f, double width, double height) {
    SplitMix& rng = *rng_;
    double ground = std::min(height, rng.Uniform(3.6, 4.4));
    const double floor_height = rng.Uniform(options_.floor_height_min, options_.floor_height_max);
    const double parapet = rng.Uniform(0.7, 1.2);
    const int upper = std::max(0, static_cast<int>((height - ground - parapet) / floor_height));
    const double end_margin = rng.Uniform(0.3, 0.9);
    const double usable = width - 2 * end_margin;
    if (usable < 1.5) {  // too narrow for openings: a plain wall
      WallQuad(f, 0, width, 0, height, 0, f.normal, Surface::kWall);
      return;
    }
    const int bays = std::max(1, static_cast<int>(std::lround(usable / rng.Uniform(2.4, 3.6))));
    const double bay = usable / bays;
    const double window_width = bay * rng.Uniform(0.42, 0.64);
    const double sill = rng.Uniform(0.8, 1.0);
    const double window_height =
        std::min(floor_height * rng.Uniform(0.45, 0.62), floor_height - sill - 0.25);

    // Ground floor: doors, shop windows, or wall.
    std::vector<Opening> openings;
    for (int b = 0; b < bays; ++b) {
      const double centre = end_margin + (b + 0.5) * bay;
      const double kind = rng.Uniform();
      if (kind < 0.25) {
        const double w = std::min(bay - 0.4, rng.Uniform(1.0, 1.4));
        const double h = std::min(ground - 0.5, rng.Uniform(2.2, 2.6));
        if (w > 0.5 && h > 1.5)
          openings.push_back({centre - w / 2, centre + w / 2, 0.0, h, Surface::kDoor});
      } else if (kind < 0.7) {
        const double w = bay * rng.Uniform(0.6, 0.82);
        const double v0 = rng.Uniform(0.4, 0.7), v1 = ground - rng.Uniform(0.45, 0.8);
        if (v1 - v0 > 0.8)
          openings.push_back({centre - w / 2, centre + w / 2, v0, v1, Surface::kGlass});
      }
    }
    Row(f, width, 0.0, ground, openings);
    // A string course between the ground floor and the storeys.
    if (upper > 0) FacadeBox(f, 0, width, ground - 0.25, ground, 0.0, 0.15, Surface::kTrim);

    for (int k = 0; k < upper; ++k) {
      const double va = ground + k * floor_height, vb = va + floor_height;
      openings.clear();
      for (int b = 0; b < bays; ++b) {
        const double centre = end_margin + (b + 0.5) * bay;
        openings.push_back({centre - window_width / 2, centre + window_width / 2, va + sill,
                            va + sill + window_height, Surface::kGlass});
        if (rng.Bernoulli(options_.balcony_probability)) {
          const double u0 = centre - window_width / 2 - 0.3, u1 = centre + window_width / 2 + 0.3;
          const double depth = rng.Uniform(0.7, 1.1);
          FacadeBox(f, u0, u1, va + 0.02, va + 0.17, 0.0, depth, Surface::kTrim);
          FacadeBox(f, u0, u1, va + 0.17, va + 1.0, depth - 0.06, depth, Surface::kTrim);
        }
      }
      Row(f, width, va, vb, openings);
    }
    const double top = ground + upper * floor_height;
    WallQuad(f, 0, width, top, height, 0, f.normal, Surface::kWall);
    if (options_.cornice_depth > 0 && height - top > 0.5) {
      FacadeBox(f, 0, width, height - 0.45, height, 0.0, options_.cornice_depth, Surface::kTrim);
    }
  }

 private:
  const SynthCityOptions& options_;
  MeshBuilder* builder_;
  SplitMix* rng_;
  uint32_t object_;
};

struct Rect {
  double x0, y0, x1, y1;
};

// A building: its footprint, which of its sides face a street (-x, +x, -y, +y), its height.
void AddBuilding(const SynthCityOptions& options, const Rect& r, std::array<bool, 4> street_sides,
                 double base, MeshBuilder* builder, SplitMix* rng) {
  const uint32_t object = builder->NewObject();
  const double height = rng->Uniform(options.building_min_height, options.building_max_height);
  const double top = base + height;
  builder->AddQuad({r.x0, r.y0, top}, {r.x1, r.y0, top}, {r.x1, r.y1, top}, {r.x0, r.y1, top},
                   Vector3d::UnitZ(), Surface::kRoof, object);
  FacadeMaker maker(options, builder, rng, object);
  // Sides in order -x, +x, -y, +y: the facade frame seen from outside.
  const std::array<FacadeFrame, 4> frames = {
      FacadeFrame{{r.x0, r.y1, base}, -Vector3d::UnitY(), -Vector3d::UnitX()},
      FacadeFrame{{r.x1, r.y0, base}, Vector3d::UnitY(), Vector3d::UnitX()},
      FacadeFrame{{r.x0, r.y0, base}, Vector3d::UnitX(), -Vector3d::UnitY()},
      FacadeFrame{{r.x1, r.y1, base}, -Vector3d::UnitX(), Vector3d::UnitY()}};
  const std::array<double, 4> widths = {r.y1 - r.y0, r.y1 - r.y0, r.x1 - r.x0, r.x1 - r.x0};
  for (int side = 0; side < 4; ++side) {
    if (street_sides[side]) {
      maker.Facade(frames[side], widths[side], height);
    } else {
      maker.WallQuad(frames[side], 0, widths[side], 0, height, 0, frames[side].normal,
                     Surface::kWall);
    }
  }
}

// Splits [0, length] into widths in [min_width, max_width] (the last one takes the rest).
std::vector<double> SplitFrontage(double length, const SynthCityOptions& options, SplitMix* rng) {
  std::vector<double> widths;
  double remaining = length;
  while (remaining > 0.5) {
    double w = rng->Uniform(options.building_min_width, options.building_max_width);
    if (remaining - w < options.building_min_width) w = remaining;
    widths.push_back(w);
    remaining -= w;
  }
  return widths;
}

void AddBlockBuildings(const SynthCityOptions& options, const Rect& lot, double base,
                       MeshBuilder* builder, SplitMix* rng, int* count) {
  const double w = lot.x1 - lot.x0, h = lot.y1 - lot.y0;
  const double d = std::min(options.building_depth, 0.5 * std::min(w, h));
  // Corner buildings face two streets.
  AddBuilding(options, {lot.x0, lot.y0, lot.x0 + d, lot.y0 + d}, {true, false, true, false}, base,
              builder, rng);
  AddBuilding(options, {lot.x1 - d, lot.y0, lot.x1, lot.y0 + d}, {false, true, true, false}, base,
              builder, rng);
  AddBuilding(options, {lot.x0, lot.y1 - d, lot.x0 + d, lot.y1}, {true, false, false, true}, base,
              builder, rng);
  AddBuilding(options, {lot.x1 - d, lot.y1 - d, lot.x1, lot.y1}, {false, true, false, true}, base,
              builder, rng);
  *count += 4;
  // Along the sides, between the corners.
  for (int side = 0; side < 4; ++side) {
    const bool along_x = side >= 2;
    const double start = along_x ? lot.x0 + d : lot.y0 + d;
    const double length = along_x ? w - 2 * d : h - 2 * d;
    if (length < 0.5) continue;
    double s = start;
    for (double width : SplitFrontage(length, options, rng)) {
      const double depth = d * rng->Uniform(0.6, 1.0);
      Rect r;
      std::array<bool, 4> street{};
      street[side] = true;
      switch (side) {
        case 0:
          r = {lot.x0, s, lot.x0 + depth, s + width};
          break;
        case 1:
          r = {lot.x1 - depth, s, lot.x1, s + width};
          break;
        case 2:
          r = {s, lot.y0, s + width, lot.y0 + depth};
          break;
        default:
          r = {s, lot.y1 - depth, s + width, lot.y1};
          break;
      }
      AddBuilding(options, r, street, base, builder, rng);
      ++*count;
      s += width;
    }
  }
}

// Icosahedron subdivided `levels` times, on the unit sphere, faces outward.
void UnitSphere(int levels, std::vector<Vector3d>* vertices, std::vector<Eigen::Vector3i>* faces) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  *vertices = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
               {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vector3d& v : *vertices) v.normalize();
  *faces = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
            {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
            {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> midpoints;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoints.find(key);
      if (it != midpoints.end()) return it->second;
      vertices->push_back(((*vertices)[a] + (*vertices)[b]).normalized());
      const int index = static_cast<int>(vertices->size()) - 1;
      midpoints[key] = index;
      return index;
    };
    std::vector<Eigen::Vector3i> finer;
    for (const Eigen::Vector3i& f : *faces) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      finer.insert(finer.end(), {{f[0], ab, ca}, {f[1], bc, ab}, {f[2], ca, bc}, {ab, bc, ca}});
    }
    *faces = std::move(finer);
  }
}

void AddTree(const SynthCityOptions& options, const Vector3d& foot, double max_radius,
             MeshBuilder* builder, SplitMix* rng) {
  const uint32_t trunk = builder->NewObject();
  const double trunk_height = rng->Uniform(2.3, 3.0), half = 0.14;
  const double radius = std::min(rng->Uniform(1.3, 1.9), max_radius);
  const Vector3d centre = foot + Vector3d(0, 0, trunk_height + 0.75 * radius);
  builder->AddBox(foot + Vector3d(-half, -half, 0),
                  foot + Vector3d(half, half, trunk_height + 0.3 * radius), Surface::kTrunk, trunk,
                  {false, false, false, false, true, false});
  std::vector<Vector3d> sphere;
  std::vector<Eigen::Vector3i> faces;
  UnitSphere(options.tree_crown_subdivisions, &sphere, &faces);
  const Vector3d scale(radius * rng->Uniform(0.85, 1.0), radius * rng->Uniform(0.85, 1.0),
                       radius * rng->Uniform(0.8, 1.1));
  for (Vector3d& v : sphere) v = centre + (v * rng->Uniform(0.85, 1.0)).cwiseProduct(scale);
  const uint32_t crown = builder->NewObject();
  for (const Eigen::Vector3i& f : faces) {
    builder->AddTriangle(sphere[f[0]], sphere[f[1]], sphere[f[2]], Surface::kCrown, crown);
  }
}

// A parked car centred at `centre` on the road, `along` its axis (unit x or y).
void AddCar(const Vector3d& centre, const Vector3d& along, MeshBuilder* builder, SplitMix* rng) {
  const uint32_t object = builder->NewObject();
  const Vector3d across(-along.y(), along.x(), 0);
  const double length = rng->Uniform(3.9, 4.7), width = rng->Uniform(1.7, 1.85);
  auto box = [&](double l0, double l1, double w, double z0, double z1) {
    const Vector3d a = centre + l0 * along - 0.5 * w * across + Vector3d(0, 0, z0);
    const Vector3d b = centre + l1 * along + 0.5 * w * across + Vector3d(0, 0, z1);
    builder->AddBox(a.cwiseMin(b), a.cwiseMax(b), Surface::kCar, object,
                    {false, false, false, false, true, false});
  };
  box(-0.5 * length, 0.5 * length, width, 0.15, rng->Uniform(0.9, 1.05));
  const double cabin = length * rng->Uniform(0.45, 0.6), shift = rng->Uniform(-0.4, 0.1);
  box(shift - 0.5 * cabin, shift + 0.5 * cabin, width - 0.15, 1.05, rng->Uniform(1.4, 1.6));
}

}  // namespace

CityScene BuildCity(const SynthCityOptions& options, uint64_t seed) {
  CityScene scene;
  MeshBuilder builder(&scene);
  SplitMix rng(Hash(seed, 0xC17));
  const double rhw = options.road_half_width;
  const int nx = options.loop_blocks_x + 2 * options.ring_blocks;
  const int ny = options.loop_blocks_y + 2 * options.ring_blocks;

  // Street centre lines, then centred on the loop.
  StreetGrid& streets = scene.streets;
  streets.road_half_width = rhw;
  auto make_lines = [&](int count, double size, int first, int last) {
    std::vector<double> lines = {0.0};
    for (int i = 0; i < count; ++i) {
      const double block = size * (1.0 + rng.Uniform(-options.block_jitter, options.block_jitter));
      lines.push_back(lines.back() + 2 * rhw + block);
    }
    const double middle = 0.5 * (lines[first] + lines[last]);
    for (double& x : lines) x -= middle;
    return lines;
  };
  streets.loop_x_first = options.ring_blocks;
  streets.loop_x_last = options.ring_blocks + options.loop_blocks_x;
  streets.loop_y_first = options.ring_blocks;
  streets.loop_y_last = options.ring_blocks + options.loop_blocks_y;
  streets.x_lines = make_lines(nx, options.block_size_x, streets.loop_x_first, streets.loop_x_last);
  streets.y_lines = make_lines(ny, options.block_size_y, streets.loop_y_first, streets.loop_y_last);

  std::vector<Rect> blocks;
  for (int i = 0; i < nx; ++i) {
    for (int j = 0; j < ny; ++j) {
      blocks.push_back({streets.x_lines[i] + rhw, streets.y_lines[j] + rhw,
                        streets.x_lines[i + 1] - rhw, streets.y_lines[j + 1] - rhw});
    }
  }

  // Ground: the cells of the grid of kerb lines that no block covers, out to a margin.
  const double margin = 120.0;
  std::vector<double> xs = {streets.x_lines.front() - margin, streets.x_lines.back() + margin};
  std::vector<double> ys = {streets.y_lines.front() - margin, streets.y_lines.back() + margin};
  for (size_t i = 0; i < streets.x_lines.size(); ++i) {
    xs.push_back(streets.x_lines[i] - rhw);
    xs.push_back(streets.x_lines[i] + rhw);
  }
  for (size_t j = 0; j < streets.y_lines.size(); ++j) {
    ys.push_back(streets.y_lines[j] - rhw);
    ys.push_back(streets.y_lines[j] + rhw);
  }
  std::sort(xs.begin(), xs.end());
  std::sort(ys.begin(), ys.end());
  for (size_t i = 0; i + 1 < xs.size(); ++i) {
    for (size_t j = 0; j + 1 < ys.size(); ++j) {
      const double cx = 0.5 * (xs[i] + xs[i + 1]), cy = 0.5 * (ys[j] + ys[j + 1]);
      const bool covered = std::any_of(blocks.begin(), blocks.end(), [&](const Rect& b) {
        return cx > b.x0 && cx < b.x1 && cy > b.y0 && cy < b.y1;
      });
      if (covered) continue;
      builder.AddQuad({xs[i], ys[j], 0}, {xs[i + 1], ys[j], 0}, {xs[i + 1], ys[j + 1], 0},
                      {xs[i], ys[j + 1], 0}, Vector3d::UnitZ(), Surface::kRoad, 0);
    }
  }

  const double kerb = options.kerb_height;
  for (const Rect& b : blocks) {
    const uint32_t slab = builder.NewObject();
    builder.AddQuad({b.x0, b.y0, kerb}, {b.x1, b.y0, kerb}, {b.x1, b.y1, kerb}, {b.x0, b.y1, kerb},
                    Vector3d::UnitZ(), Surface::kSidewalk, slab);
    if (kerb > 0) {
      builder.AddBox({b.x0, b.y0, 0}, {b.x1, b.y1, kerb}, Surface::kKerb, slab,
                     {false, false, false, false, true, true});
    }
    const double sw = options.sidewalk_width;
    AddBlockBuildings(options, {b.x0 + sw, b.y0 + sw, b.x1 - sw, b.y1 - sw}, kerb, &builder, &rng,
                      &scene.num_buildings);

    // Street furniture along the four sides: poles near the kerb, trees a little further in,
    // parked cars on the road along the kerb.
    for (int side = 0; side < 4; ++side) {
      const bool along_x = side >= 2;
      const double lo = along_x ? b.x0 : b.y0, hi = along_x ? b.x1 : b.y1;
      auto point_at = [&](double s, double inset) -> Vector3d {
        switch (side) {
          case 0:
            return {b.x0 + inset, s, kerb};
          case 1:
            return {b.x1 - inset, s, kerb};
          case 2:
            return {s, b.y0 + inset, kerb};
          default:
            return {s, b.y1 - inset, kerb};
        }
      };
      for (double s = lo + 2.0 + rng.Uniform(0, options.pole_spacing); s < hi - 2.0;
           s += options.pole_spacing * rng.Uniform(0.6, 1.4)) {
        const Vector3d foot = point_at(s, 0.45);
        const double height = rng.Uniform(4.5, 6.5);
        builder.AddBox(foot + Vector3d(-0.07, -0.07, 0), foot + Vector3d(0.07, 0.07, height),
                       Surface::kPole, builder.NewObject(),
                       {false, false, false, false, true, false});
        ++scene.num_poles;
      }
      const double tree_inset = std::min(1.2, 0.45 * sw);
      for (double s = lo + 3.0 + rng.Uniform(0, options.tree_spacing); s < hi - 3.0;
           s += options.tree_spacing * rng.Uniform(0.6, 1.4)) {
        AddTree(options, point_at(s, tree_inset), sw - tree_inset - 0.15, &builder, &rng);
        ++scene.num_trees;
      }
      const Vector3d along = along_x ? Vector3d::UnitX() : Vector3d::UnitY();
      for (double s = lo + 5.0 + rng.Uniform(0, 0.5 * options.parked_car_spacing); s < hi - 5.0;
           s += options.parked_car_spacing * rng.Uniform(0.6, 1.4)) {
        Vector3d centre = point_at(s, -1.0);
        centre.z() = 0.0;
        AddCar(centre, along, &builder, &rng);
        ++scene.num_cars;
      }
    }
  }

  // Float-representable vertices (the PLY stores floats), then the normals of the rounded
  // triangles.
  for (Vector3d& v : scene.mesh.vertices) v = v.cast<float>().cast<double>();
  scene.normals.reserve(scene.mesh.triangles.size());
  for (const Eigen::Vector3i& t : scene.mesh.triangles) {
    const Vector3d& a = scene.mesh.vertices[t[0]];
    scene.normals.push_back(
        (scene.mesh.vertices[t[1]] - a).cross(scene.mesh.vertices[t[2]] - a).normalized());
  }
  scene.mesh.labels.reserve(scene.surfaces.size());
  for (const Surface surface : scene.surfaces) {
    scene.mesh.labels.push_back(static_cast<uint8_t>(surface));
  }
  return scene;
}

const std::vector<std::string>& SurfaceNames() {
  static_assert(static_cast<int>(Surface::kCar) == 12, "a name for every Surface, in order");
  static const std::vector<std::string> names = {"road",  "sidewalk", "kerb", "wall", "reveal",
                                                 "glass", "door",     "roof", "trim", "pole",
                                                 "trunk", "crown",    "car"};
  return names;
}

}  // namespace omni::synth

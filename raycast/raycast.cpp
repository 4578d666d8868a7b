#include "raycast/raycast.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "calib/error.h"

namespace omni {

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  }
  const double denominator = va + vb + vc;
  if (!(std::abs(denominator) > 0.0)) {  // degenerate: nearest of the three edges' ends
    const double da = (p - a).squaredNorm(), db = (p - b).squaredNorm(), dc = (p - c).squaredNorm();
    return da <= db && da <= dc ? a : db <= dc ? b : c;
  }
  const double v = vb / denominator, w = vc / denominator;
  return a + v * ab + w * ac;
}

namespace {

struct ClosestQuery {
  const std::vector<Eigen::Vector3d>* vertices;
  const std::vector<Eigen::Vector3i>* triangles;
  Eigen::Vector3d point;
  double best_distance;
  int best_triangle = -1;
};

bool ClosestPointCallback(RTCPointQueryFunctionArguments* args) {
  auto* query = static_cast<ClosestQuery*>(args->userPtr);
  const Eigen::Vector3i& tri = (*query->triangles)[args->primID];
  const auto& v = *query->vertices;
  const Eigen::Vector3d closest =
      ClosestPointOnTriangle(query->point, v[tri[0]], v[tri[1]], v[tri[2]]);
  const double distance = (closest - query->point).norm();
  if (distance < query->best_distance) {
    query->best_distance = distance;
    query->best_triangle = static_cast<int>(args->primID);
    args->query->radius = static_cast<float>(distance);
    return true;
  }
  return false;
}

}  // namespace

struct RayCaster::Impl {
  RayCasterOptions options;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  Eigen::Vector3d origin;                 // subtracted from every coordinate before Embree sees it
  std::vector<Eigen::Vector3d> vertices;  // shifted
  std::vector<Eigen::Vector3i> triangles;
  Eigen::Vector3d min_corner, max_corner;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

RayCaster::RayCaster(const TriangleMesh& mesh, const RayCasterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (mesh.triangles.empty()) throw InputError("", "triangles", "the mesh has no triangle");
  const int num_vertices = static_cast<int>(mesh.vertices.size());
  for (const auto& tri : mesh.triangles) {
    if (tri.minCoeff() < 0 || tri.maxCoeff() >= num_vertices) {
      throw InputError("", "triangles",
                       "a triangle indexes a vertex out of the " + std::to_string(num_vertices));
    }
  }
  Impl& impl = *impl_;
  impl.options = options;
  impl.min_corner = impl.max_corner = mesh.vertices[mesh.triangles[0][0]];
  for (const auto& v : mesh.vertices) {
    impl.min_corner = impl.min_corner.cwiseMin(v);
    impl.max_corner = impl.max_corner.cwiseMax(v);
  }
  impl.origin = options.recentre ? Eigen::Vector3d(0.5 * (impl.min_corner + impl.max_corner))
                                 : Eigen::Vector3d::Zero();
  impl.vertices.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) impl.vertices.push_back(v - impl.origin);
  impl.triangles = mesh.triangles;

  impl.device = rtcNewDevice(nullptr);
  if (!impl.device) throw std::runtime_error("Embree: cannot create a device");
  impl.scene = rtcNewScene(impl.device);
  if (options.robust) rtcSetSceneFlags(impl.scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl.scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertex_buffer = static_cast<float*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                              3 * sizeof(float), impl.vertices.size()));
  for (size_t i = 0; i < impl.vertices.size(); ++i) {
    for (int k = 0; k < 3; ++k) vertex_buffer[3 * i + k] = static_cast<float>(impl.vertices[i][k]);
  }
  auto* index_buffer = static_cast<unsigned*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                              3 * sizeof(unsigned), impl.triangles.size()));
  for (size_t i = 0; i < impl.triangles.size(); ++i) {
    for (int k = 0; k < 3; ++k)
      index_buffer[3 * i + k] = static_cast<unsigned>(impl.triangles[i][k]);
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(impl.scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(impl.scene);
  if (rtcGetDeviceError(impl.device) != RTC_ERROR_NONE) {
    throw std::runtime_error("Embree: cannot build the scene");
  }
}

RayCaster::~RayCaster() = default;
RayCaster::RayCaster(RayCaster&&) noexcept = default;
RayCaster& RayCaster::operator=(RayCaster&&) noexcept = default;

RayHit RayCaster::Cast(const Ray& ray) const {
  const Eigen::Vector3d origin = ray.origin - impl_->origin;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  if (impl_->options.coherent) context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  RTCRayHit ray_hit;
  ray_hit.ray.org_x = static_cast<float>(origin.x());
  ray_hit.ray.org_y = static_cast<float>(origin.y());
  ray_hit.ray.org_z = static_cast<float>(origin.z());
  ray_hit.ray.dir_x = static_cast<float>(ray.direction.x());
  ray_hit.ray.dir_y = static_cast<float>(ray.direction.y());
  ray_hit.ray.dir_z = static_cast<float>(ray.direction.z());
  ray_hit.ray.tnear = 0.0f;
  ray_hit.ray.tfar = std::isfinite(ray.max_distance) ? static_cast<float>(ray.max_distance)
                                                     : std::numeric_limits<float>::infinity();
  ray_hit.ray.time = 0.0f;
  ray_hit.ray.mask = 0xFFFFFFFFu;
  ray_hit.ray.id = 0;
  ray_hit.ray.flags = 0;
  ray_hit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  ray_hit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &ray_hit);
  RayHit hit;
  if (ray_hit.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
    hit.triangle = static_cast<int>(ray_hit.hit.primID);
    hit.distance = ray_hit.ray.tfar;
    hit.u = ray_hit.hit.u;
    hit.v = ray_hit.hit.v;
  }
  return hit;
}

void RayCaster::CastPacket(const Ray* rays, const bool* valid, RayHit* hits) const {
  static_assert(kPacketSize == 8, "CastPacket traces Embree's 8-wide packets");
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  if (impl_->options.coherent) context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  RTCRayHit8 packet;
  alignas(32) int valid_mask[8];
  for (int k = 0; k < 8; ++k) {
    valid_mask[k] = valid[k] ? -1 : 0;
    const Eigen::Vector3d origin =
        valid[k] ? Eigen::Vector3d(rays[k].origin - impl_->origin) : Eigen::Vector3d::Zero();
    const Eigen::Vector3d direction = valid[k] ? rays[k].direction : Eigen::Vector3d::UnitZ();
    packet.ray.org_x[k] = static_cast<float>(origin.x());
    packet.ray.org_y[k] = static_cast<float>(origin.y());
    packet.ray.org_z[k] = static_cast<float>(origin.z());
    packet.ray.dir_x[k] = static_cast<float>(direction.x());
    packet.ray.dir_y[k] = static_cast<float>(direction.y());
    packet.ray.dir_z[k] = static_cast<float>(direction.z());
    packet.ray.tnear[k] = 0.0f;
    packet.ray.tfar[k] = valid[k] && std::isfinite(rays[k].max_distance)
                             ? static_cast<float>(rays[k].max_distance)
                             : std::numeric_limits<float>::infinity();
    packet.ray.mask[k] = 0xFFFFFFFFu;
    packet.ray.flags[k] = 0;
    packet.ray.time[k] = 0.0f;
    packet.ray.id[k] = k;
    packet.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
    packet.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect8(valid_mask, impl_->scene, &context, &packet);
  for (int k = 0; k < 8; ++k) {
    hits[k] = RayHit{};
    if (valid[k] && packet.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID) {
      hits[k].triangle = static_cast<int>(packet.hit.primID[k]);
      hits[k].distance = packet.ray.tfar[k];
      hits[k].u = packet.hit.u[k];
      hits[k].v = packet.hit.v[k];
    }
  }
}

std::vector<RayHit> RayCaster::CastMany(const std::vector<Ray>& rays) const {
  std::vector<RayHit> hits(rays.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 1024),
                    [&](const tbb::blocked_range<size_t>& range) {
                      for (size_t i = range.begin(); i != range.end(); ++i) hits[i] = Cast(rays[i]);
                    });
  return hits;
}

RayHit RayCaster::Closest(const Eigen::Vector3d& point, double max_distance) const {
  ClosestQuery query{&impl_->vertices, &impl_->triangles, point - impl_->origin, max_distance};
  RTCPointQuery point_query;
  point_query.x = static_cast<float>(query.point.x());
  point_query.y = static_cast<float>(query.point.y());
  point_query.z = static_cast<float>(query.point.z());
  point_query.time = 0.0f;
  point_query.radius = std::isfinite(max_distance) ? static_cast<float>(max_distance)
                                                   : std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &point_query, &context, ClosestPointCallback, &query);
  RayHit hit;
  if (query.best_triangle >= 0) {
    hit.triangle = query.best_triangle;
    hit.distance = query.best_distance;
  }
  return hit;
}

std::vector<double> RayCaster::DistancesTo(const std::vector<Eigen::Vector3d>& points,
                                           double max_distance) const {
  std::vector<double> distances(points.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256),
                    [&](const tbb::blocked_range<size_t>& range) {
                      for (size_t i = range.begin(); i != range.end(); ++i) {
                        distances[i] = Closest(points[i], max_distance).distance;
                      }
                    });
  return distances;
}

Eigen::Vector3d RayCaster::TriangleNormal(int triangle) const {
  const Eigen::Vector3i& tri = impl_->triangles.at(triangle);
  const auto& v = impl_->vertices;
  const Eigen::Vector3d n = (v[tri[1]] - v[tri[0]]).cross(v[tri[2]] - v[tri[0]]);
  const double norm = n.norm();
  return norm > 0.0 ? Eigen::Vector3d(n / norm) : Eigen::Vector3d::Zero();
}

size_t RayCaster::NumTriangles() const { return impl_->triangles.size(); }
Eigen::Vector3d RayCaster::MinCorner() const { return impl_->min_corner; }
Eigen::Vector3d RayCaster::MaxCorner() const { return impl_->max_corner; }

}  // namespace omni

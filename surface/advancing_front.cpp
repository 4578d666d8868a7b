#include "surface/advancing_front.h"

#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <array>
#include <cmath>
#include <iterator>

#include "calib/error.h"

namespace omni {

namespace {

// CGAL's default priority (the radius of the facet's smallest Delaunay sphere), with the facets
// of an edge longer than a bound out of reach.
struct BoundedEdgePriority {
  double max_squared_edge = 0.0;  // 0: no bound

  template <typename AdvancingFront, typename CellHandle>
  double operator()(const AdvancingFront& front, CellHandle& cell, const int& index) const {
    if (max_squared_edge > 0.0) {
      for (int i = 1; i <= 3; ++i) {
        for (int j = i + 1; j <= 3; ++j) {
          if (CGAL::squared_distance(cell->vertex((index + i) % 4)->point(),
                                     cell->vertex((index + j) % 4)->point()) > max_squared_edge)
            return front.infinity();
        }
      }
    }
    return front.smallest_radius_delaunay_sphere(cell, index);
  }
};

}  // namespace

std::string AdvancingFrontOptions::Check() const {
  if (!(max_edge >= 0.0) || !std::isfinite(max_edge)) return "max_edge: expected 0 or more";
  if (!(beta > 0.0) || !(beta < M_PI)) return "beta: expected an angle in (0, pi) radians";
  return {};
}

TriangleMesh AdvancingFrontSurface(const std::vector<Eigen::Vector3d>& points,
                                   const AdvancingFrontOptions& options,
                                   std::vector<size_t>* input_of_vertex) {
  ThrowIfInvalid(options.Check(), "AdvancingFrontOptions");
  if (input_of_vertex) input_of_vertex->clear();
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  TriangleMesh mesh;
  if (points.size() < 3) return mesh;
  std::vector<Kernel::Point_3> cgal_points;
  cgal_points.reserve(points.size());
  for (const Eigen::Vector3d& p : points) cgal_points.emplace_back(p.x(), p.y(), p.z());
  std::vector<std::array<std::size_t, 3>> facets;
  BoundedEdgePriority priority;
  priority.max_squared_edge = options.max_edge * options.max_edge;
  CGAL::advancing_front_surface_reconstruction(cgal_points.begin(), cgal_points.end(),
                                               std::back_inserter(facets), priority,
                                               /*radius_ratio_bound=*/5.0, options.beta);
  // Only the points in a triangle are vertices, in their input order.
  std::vector<int> vertex_of(points.size(), -1);
  for (const auto& facet : facets) {
    for (std::size_t index : facet) vertex_of.at(index) = 0;
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (vertex_of[i] < 0) continue;
    vertex_of[i] = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(points[i]);
    if (input_of_vertex) input_of_vertex->push_back(i);
  }
  mesh.triangles.reserve(facets.size());
  for (const auto& facet : facets) {
    mesh.triangles.emplace_back(vertex_of[facet[0]], vertex_of[facet[1]], vertex_of[facet[2]]);
  }
  return mesh;
}

}  // namespace omni

#pragma once
// Genus refinement of step 6 (paper §4.6) on a whole DelaunayMesh, for tests and tools: the
// sculptor runs the same procedure on the cells of each keyframe (surface/sculptor.h).

#include <cstddef>

#include "surface/delaunay.h"
#include "surface/sculptor.h"

namespace omni {

struct GenusRefinementStats {
  size_t free_before = 0, free_after = 0;  // finite cells of F outside O
  size_t groups = 0;                       // groups of cells added at once
  long euler_change = 0;                   // Δχ of δO
};

// Adds groups of cells of F \ O to O while δO stays a 2-manifold (GenusRefinementOptions),
// over all finite cells. δO must be a 2-manifold on entry.
GenusRefinementStats RefineGenus(DelaunayMesh& mesh, const GenusRefinementOptions& options);

}  // namespace omni

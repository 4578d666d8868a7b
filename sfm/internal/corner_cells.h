#pragma once
// INTERNAL to sfm/*.cpp: the corners of an image by cell of a uniform grid, to find those near
// a place without visiting them all (the ZNCC matching's search discs, the map-point search's
// neighbourhoods).

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

namespace omni::internal {

// Squared distance from `point` to the segment from `start` to `start + along` (to `start` when
// `along` is zero).
inline double SquaredDistanceToSegment(const Eigen::Vector2d& point, const Eigen::Vector2d& start,
                                       const Eigen::Vector2d& along) {
  Eigen::Vector2d offset = point - start;
  const double length_squared = along.squaredNorm();
  if (length_squared > 0.0)
    offset -= std::clamp(offset.dot(along) / length_squared, 0.0, 1.0) * along;
  return offset.squaredNorm();
}

// The corners by cell of a cols × rows grid of cells of side `cell` (pixels) from the origin, a
// corner outside the grid in its nearest cell; in index order per cell, as compressed rows (one
// allocation for all the cells, not one per cell). With `selected`, only the corners marked in
// it.
class CornerCells {
 public:
  CornerCells(const std::vector<Eigen::Vector2d>& corners, int cols, int rows, double cell,
              const std::vector<char>* selected = nullptr)
      : cell_(cell), cols_(cols), rows_(rows), start_(static_cast<size_t>(cols) * rows + 1, 0) {
    std::vector<int> cell_of(corners.size(), -1);
    for (size_t i = 0; i < corners.size(); ++i) {
      if (selected && !(*selected)[i]) continue;
      cell_of[i] = Row(corners[i].y()) * cols_ + Col(corners[i].x());
      ++start_[cell_of[i] + 1];
    }
    for (size_t k = 1; k < start_.size(); ++k) start_[k] += start_[k - 1];
    indices_.resize(start_.back());
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (size_t i = 0; i < corners.size(); ++i)
      if (cell_of[i] >= 0) indices_[fill[cell_of[i]]++] = static_cast<int>(i);
  }

  // The column and row of the cell holding x or y (clamped to the grid).
  int Col(double x) const {
    return static_cast<int>(std::clamp(std::floor(x / cell_), 0.0, cols_ - 1.0));
  }
  int Row(double y) const {
    return static_cast<int>(std::clamp(std::floor(y / cell_), 0.0, rows_ - 1.0));
  }

  // The corners of cell (col, row), in index order.
  struct Range {
    const int* first;
    const int* last;
    const int* begin() const { return first; }
    const int* end() const { return last; }
  };
  Range Cell(int col, int row) const {
    const size_t k = static_cast<size_t>(row) * cols_ + col;
    return {indices_.data() + start_[k], indices_.data() + start_[k + 1]};
  }

  // Indices (ascending) of the corners in the cells that meet the bounding box of the disc.
  void Near(const Eigen::Vector2d& centre, double radius, std::vector<int>* out) const {
    out->clear();
    for (int row = Row(centre.y() - radius); row <= Row(centre.y() + radius); ++row)
      for (int col = Col(centre.x() - radius); col <= Col(centre.x() + radius); ++col) {
        const Range range = Cell(col, row);
        out->insert(out->end(), range.begin(), range.end());
      }
    std::sort(out->begin(), out->end());
  }

  // The same for the points within `radius` of the segment from `start` to `start + along`:
  // the cells of its bounding box whose centre lies within radius plus half a cell's diagonal
  // of the segment (a superset of the cells that meet the band).
  void NearSegment(const Eigen::Vector2d& start, const Eigen::Vector2d& along, double radius,
                   std::vector<int>* out) const {
    out->clear();
    const Eigen::Vector2d end = start + along;
    const double reach = radius + 0.5 * std::sqrt(2.0) * cell_, reach_squared = reach * reach;
    for (int row = Row(std::min(start.y(), end.y()) - radius);
         row <= Row(std::max(start.y(), end.y()) + radius); ++row)
      for (int col = Col(std::min(start.x(), end.x()) - radius);
           col <= Col(std::max(start.x(), end.x()) + radius); ++col) {
        const Eigen::Vector2d cell_centre((col + 0.5) * cell_, (row + 0.5) * cell_);
        if (SquaredDistanceToSegment(cell_centre, start, along) > reach_squared) continue;
        const Range range = Cell(col, row);
        out->insert(out->end(), range.begin(), range.end());
      }
    std::sort(out->begin(), out->end());
  }

 private:
  double cell_;
  int cols_, rows_;
  std::vector<int> start_, indices_;
};

}  // namespace omni::internal

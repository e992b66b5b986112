// A box chair written as an OBJ under a known transform, for the tests of mesh chairs: what is
// found from the mesh then has an answer independent of the finder.
#pragma once

#include <Eigen/Geometry>
#include <sstream>
#include <string>

#include "envs/chair.h"

namespace perch {

// A box chair's boxes as an OBJ (12 outward triangles each), each point p written as
// file = R_up^-1 (yaw(p) + offset) / scale: a file in `scale` units with `up` as its up axis.
inline std::string BoxesAsObj(const Chair& c, double yaw, const Eigen::Vector3d& offset,
                              double scale, bool y_up) {
  std::ostringstream s;
  int base = 1;
  const Eigen::Matrix3d rz = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (const ChairBox& b : c.boxes) {
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d p((k & 1) ? b.max.x() : b.min.x(), (k & 2) ? b.max.y() : b.min.y(),
                              (k & 4) ? b.max.z() : b.min.z());
      Eigen::Vector3d w = (rz * p + offset) / scale;
      if (y_up) w = Eigen::Vector3d(w.x(), w.z(), -w.y());  // z-up -> y-up
      s << "v " << w.x() << " " << w.y() << " " << w.z() << "\n";
    }
    // Corner index bits: x = 1, y = 2, z = 4; faces wound counter-clockwise seen from outside.
    const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                             {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : quads) {
      s << "f " << base + q[0] << " " << base + q[1] << " " << base + q[2] << "\n";
      s << "f " << base + q[0] << " " << base + q[2] << " " << base + q[3] << "\n";
    }
    base += 8;
  }
  return s.str();
}

}  // namespace perch

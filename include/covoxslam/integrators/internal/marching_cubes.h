#pragma once
// Marching cubes without a case table: the iso-surface inside one cube is found by connecting
// the zero crossings on each of the six faces into segments and chaining the segments into closed
// loops, each triangulated as a fan. This gives the same polygons as the classic 256-case table
// for the unambiguous cases, and resolves an ambiguous face (two diagonal corners inside) by the
// sign of the face centre (the mean of its corners). The decision uses only the face's own four
// values, so the two cubes sharing a face always agree and the mesh is watertight.
// Triangles are oriented so their normals point towards positive distances (free space).
#include <cstdint>

#include "covoxslam/core/macros.h"
#include "covoxslam/core/vec3.h"

namespace covox::integrators::marching_cubes {

// Corner c of a cube sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
// Edge e runs along axis e / 4 from corner kEdgeStart[e] to kEdgeStart[e] + (1 << axis).
COVOX_HD_INLINE int edge_start(int e) {
  // axis x: corners 0,2,4,6; y: 0,1,4,5; z: 0,1,2,3
  const int m = e & 3;
  switch (e >> 2) {
    case 0:
      return m * 2;
    case 1:
      return (m & 1) | ((m & 2) << 1);
    default:
      return m;
  }
}
COVOX_HD_INLINE int edge_axis(int e) { return e >> 2; }
COVOX_HD_INLINE int edge_end(int e) { return edge_start(e) + (1 << edge_axis(e)); }

// The edge joining two corners that differ in one bit.
COVOX_HD_INLINE int edge_between(int a, int b) {
  const int low = a < b ? a : b, bit = a ^ b;
  const int axis = bit == 1 ? 0 : (bit == 2 ? 1 : 2);
  // Index m of the start corner among the four starts of this axis.
  int m = 0;
  if (axis == 0)
    m = low >> 1;
  else if (axis == 1)
    m = (low & 1) | ((low >> 2) << 1);
  else
    m = low & 3;
  return axis * 4 + m;
}

// Corners of each face in cyclic order.
COVOX_HD_INLINE int face_corner(int face, int k) {
  // x=0: 0,2,6,4  x=1: 1,3,7,5  y=0: 0,1,5,4  y=1: 2,3,7,6  z=0: 0,1,3,2  z=1: 4,5,7,6
  const int table[6][4] = {{0, 2, 6, 4}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 5, 7, 6}};
  return table[face][k];
}

COVOX_HD_INLINE bool inside(float value) { return value < 0.0f; }

// Zero crossing on edge e of a cube whose corner c is at corner_position(c).
COVOX_HD_INLINE float crossing_fraction(const float* values, int e) {
  const float a = values[edge_start(e)], b = values[edge_end(e)];
  return a / (a - b);
}

// The crossing edges of a cube, each with its two partners: the crossing edges that share one of
// its faces and that the face's segment joins it to (-1 where none).
struct EdgeLoops {
  int8_t partner[12][2];

  COVOX_HD_INLINE void link(int a, int b) {
    partner[a][partner[a][0] < 0 ? 0 : 1] = static_cast<int8_t>(b);
    partner[b][partner[b][0] < 0 ? 0 : 1] = static_cast<int8_t>(a);
  }
};

// The segments of one face (signs: bit c set when corner c is inside). Two crossings give one
// segment; four (alternating corners) give two, which cut off the corners on the other side of
// the face centre from corner 0.
COVOX_HD_INLINE void link_face_crossings(const float* values, int signs, int face,
                                         EdgeLoops* loops) {
  int corner[4];
  bool in[4];
  for (int k = 0; k < 4; ++k) {
    corner[k] = face_corner(face, k);
    in[k] = (signs >> corner[k]) & 1;
  }
  int crossing_edges[4];
  int crossings = 0;
  for (int k = 0; k < 4; ++k) {
    if (in[k] != in[(k + 1) & 3])
      crossing_edges[crossings++] = edge_between(corner[k], corner[(k + 1) & 3]);
  }
  if (crossings == 2) {
    loops->link(crossing_edges[0], crossing_edges[1]);
    return;
  }
  if (crossings != 4) return;
  // Alternating corners: crossing_edges[k] lies between corner k and k + 1.
  const float centre =
      0.25f * (values[corner[0]] + values[corner[1]] + values[corner[2]] + values[corner[3]]);
  if (inside(centre) == in[0]) {
    // corners 0 and 2 are joined through the centre: cut off corners 1 and 3
    loops->link(crossing_edges[0], crossing_edges[1]);
    loops->link(crossing_edges[2], crossing_edges[3]);
  } else {
    // corners 1 and 3 are joined: cut off corners 0 and 2
    loops->link(crossing_edges[3], crossing_edges[0]);
    loops->link(crossing_edges[1], crossing_edges[2]);
  }
}

// Walks each closed loop of partners once and fan-triangulates it; returns the triangle count.
template <class Emit>
COVOX_HD_INLINE int emit_loop_fans(const EdgeLoops& loops, Emit&& emit) {
  bool visited[12] = {false, false, false, false, false, false,
                      false, false, false, false, false, false};
  int triangles = 0;
  for (int start = 0; start < 12; ++start) {
    if (loops.partner[start][0] < 0 || visited[start]) continue;
    int loop[12];
    int length = 0;
    int previous = -1, current = start;
    do {
      visited[current] = true;
      loop[length++] = current;
      const int8_t* partner = loops.partner[current];
      const int next = partner[0] != previous ? partner[0] : partner[1];
      previous = current;
      current = next;
    } while (current != start && length < 12);
    for (int k = 1; k + 1 < length; ++k) {
      emit(loop[0], loop[k], loop[k + 1]);
      ++triangles;
    }
  }
  return triangles;
}

// Calls emit(edge_a, edge_b, edge_c) for each triangle of the cube, vertices named by cube edge.
// `values` are the 8 corner distances; orientation is fixed afterwards by orient().
template <class Emit>
COVOX_HD_INLINE int polygonize(const float* values, Emit&& emit) {
  int signs = 0;
  for (int c = 0; c < 8; ++c) signs |= inside(values[c]) ? (1 << c) : 0;
  if (signs == 0 || signs == 0xff) return 0;
  // Each crossing edge gets one partner per adjacent face.
  EdgeLoops loops;
  for (int e = 0; e < 12; ++e) loops.partner[e][0] = loops.partner[e][1] = -1;
  for (int face = 0; face < 6; ++face) link_face_crossings(values, signs, face, &loops);
  return emit_loop_fans(loops, emit);
}

// The gradient of the trilinear field at the cube centre (which way is free space).
COVOX_HD_INLINE Vec3f centre_gradient(const float* v) {
  return Vec3f((v[1] + v[3] + v[5] + v[7]) - (v[0] + v[2] + v[4] + v[6]),
               (v[2] + v[3] + v[6] + v[7]) - (v[0] + v[1] + v[4] + v[5]),
               (v[4] + v[5] + v[6] + v[7]) - (v[0] + v[1] + v[2] + v[3]));
}

// Position of edge e's crossing in cube units (corner 0 at the origin).
COVOX_HD_INLINE Vec3f crossing_point(const float* values, int e) {
  const int a = edge_start(e);
  Vec3f p(static_cast<float>(a & 1), static_cast<float>((a >> 1) & 1),
          static_cast<float>((a >> 2) & 1));
  const float t = crossing_fraction(values, e);
  const int axis = edge_axis(e);
  if (axis == 0)
    p.x += t;
  else if (axis == 1)
    p.y += t;
  else
    p.z += t;
  return p;
}

// True when triangle (a, b, c) should be flipped so that its normal points to free space.
COVOX_HD_INLINE bool needs_flip(const float* values, int a, int b, int c) {
  const Vec3f pa = crossing_point(values, a), pb = crossing_point(values, b),
              pc = crossing_point(values, c);
  const Vec3f u = pb - pa, w = pc - pa;
  const Vec3f normal(u.y * w.z - u.z * w.y, u.z * w.x - u.x * w.z, u.x * w.y - u.y * w.x);
  return normal.dot(centre_gradient(values)) < 0.0f;
}

}  // namespace covox::integrators::marching_cubes

#pragma once
// Ray queries over a Bvh (Bvh.h) for the CPU and CUDA devices from one source: plain structs, pointers and counts,
// LOOM_HD functions, no allocation, exceptions or virtual calls. Bvh builds the arrays on the host; a device copy
// of each array with the same layout, put into a BvhView, is traversed by the same functions.
//
// The answers are RayScene's (RayScene.h, EmbreeRays.h), which the tests check against Embree on random rays:
// - RayHit as RayScene gives it: instance, primitive, barycentrics (u, v) of p1 and p2, t along the unnormalised
//   direction (also inside an instance: the ray enters its object space through the inverse transform, and t is
//   the same along the carried direction);
// - a hit counts where tMin < t <= tMax (Embree's depth test), for traceable() rays only; a hidden instance
//   (Instance::visible) is never hit;
// - kRayAlphaTest: MASK and BLEND materials through surfaceCovers with the ray's coverage key;
// - kRayCullBackFaces (bvhIntersect only, as RayScene::occluded ignores it): a back face of a single-sided material
//   is passed by a new query from just beyond it (the next float of t), up to 16 faces deep, then a miss.
// Coverage keys as RayScene picks them: rayCoverageKey(o, d) for both queries (RayScene::intersect uses 0 when
// nothing is alpha-tested, where keys matter to nothing), which the overloads without a key use; camera rays pass
// cameraCoverageKey, as RayScene::intersect16 takes keys.
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/Kernel.h"
#include "loom/RayScene.h"
#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"

namespace loom {

/// A node of a binary BVH, 32 bytes. An inner node (count == 0) has its children at `index` and `index + 1`; a leaf
/// holds `count` items from `index` on (triangles of BvhArrays::triangles, or instance ids of topInstances).
struct BvhNode {
    glm::vec3 lo{0.f};
    uint32_t index = 0;
    glm::vec3 hi{0.f};
    uint32_t count = 0;
};

/// A triangle in object space, copied from its mesh in leaf order: the vertices and its index within the mesh.
struct BvhTriangle {
    glm::vec3 p0{0.f}, p1{0.f}, p2{0.f};
    uint32_t primitive = 0;
};

/// A mesh's bottom-level tree: its root in BvhArrays::nodes (kInvalidId for a mesh without triangles) and whether its
/// material is alpha-tested (MASK or BLEND: only then are its hits checked under kRayAlphaTest).
struct BvhMesh {
    uint32_t root = kInvalidId;
    uint32_t alphaTested = 0;
};

/// An instance as rays enter it: world to object space (the inverse of its world transform) and its mesh.
struct BvhInstance {
    glm::mat3 toObject{1.f};
    glm::vec3 toObjectOffset{0.f};  ///< object = toObject * world + toObjectOffset
    uint32_t mesh = 0;
};

/// A span of one flat array: `count` elements from `data`, copied with one memcpy (count * sizeof(T) bytes).
template <class T>
struct BvhSpan {
    const T* data = nullptr;
    uint32_t count = 0;
};

/// Every array a traversal reads. Bottom-level arrays (nodes, triangles, meshes) are built once; the top-level ones
/// (topNodes, topInstances, instances) change with Bvh::updateInstances. A device copy replaces each pointer with
/// the device address of a copy of the same bytes; no array holds a pointer, so nothing else changes.
struct BvhArrays {
    BvhSpan<BvhNode> nodes;          ///< the bottom-level trees of all meshes
    BvhSpan<BvhTriangle> triangles;  ///< all meshes' triangles, in leaf order
    BvhSpan<BvhMesh> meshes;         ///< one per Scene::meshes
    BvhSpan<BvhNode> topNodes;       ///< the top-level tree, root at 0; empty when nothing can be hit
    BvhSpan<uint32_t> topInstances;  ///< instance ids in top-level leaf order (visible instances with triangles)
    BvhSpan<BvhInstance> instances;  ///< one per Scene::instances
};

/// What the traversal reads: the BVH's arrays and the scene's view (materials and textures for alpha tests and
/// sidedness, instances' normal matrices for back faces). Both valid on the side that traverses.
struct BvhView {
    BvhArrays bvh;
    SceneView scene;
};

/// Depth of the traversal stack. Bvh builds trees no deeper (kBvhMaxDepth in Bvh.h), so it never overflows.
inline constexpr int kBvhStackSize = 64;

namespace bvhdetail {

/// A ray prepared for box and triangle tests: 1/d for the slabs and the shear of the watertight test (Woop, Benthin
/// and Wald, "Watertight Ray/Triangle Intersection", JCGT 2013).
struct PreparedRay {
    glm::vec3 o, d, invD;
    int kx, ky, kz;
    float sx, sy, sz;
};

LOOM_HD inline PreparedRay prepareRay(glm::vec3 o, glm::vec3 d) {
    PreparedRay r;
    r.o = o;
    r.d = d;
    r.invD = glm::vec3(1.f / d.x, 1.f / d.y, 1.f / d.z);
    const glm::vec3 a = glm::abs(d);
    r.kz = a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);
    r.kx = r.kz == 2 ? 0 : r.kz + 1;
    r.ky = r.kx == 2 ? 0 : r.kx + 1;
    if (d[r.kz] < 0.f) {  // keeps the winding, so the signs of the edge functions mean the same for every ray
        const int t = r.kx;
        r.kx = r.ky;
        r.ky = t;
    }
    r.sx = d[r.kx] / d[r.kz];
    r.sy = d[r.ky] / d[r.kz];
    r.sz = 1.f / d[r.kz];
    return r;
}

/// Whether the ray meets box [lo, hi] within [tMin, tMax]; tEnter is where it enters. The slab of each axis takes
/// its near plane by the sign of 1/d, so a zero direction component (1/d infinite) with the origin on a plane gives
/// NaN, which the comparisons drop (the axis then does not constrain). tMax is widened by 1 + 2 gamma(3) so that
/// rounding never loses a box a triangle in it is hit within (Ize, "Robust BVH Ray Traversal", JCGT 2013).
LOOM_HD inline bool hitBox(const BvhNode& n, const PreparedRay& r, float tMin, float tMax, float& tEnter) {
    float t0 = tMin, t1 = tMax * 1.0000004f;
    for (int a = 0; a < 3; ++a) {
        const bool pos = r.invD[a] >= 0.f;
        const float tn = ((pos ? n.lo[a] : n.hi[a]) - r.o[a]) * r.invD[a];
        const float tf = ((pos ? n.hi[a] : n.lo[a]) - r.o[a]) * r.invD[a];
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
    }
    tEnter = t0;
    return t0 <= t1;
}

/// The watertight ray/triangle test (Woop et al. 2013): a hit in tMin < t <= tMax (Embree's depth test) sets t and
/// the barycentrics u, v of p1 and p2. Either face. (Bvh leaves out triangles of zero area.)
/// Watertight within one mesh, but two meshes whose edges meet in world space (the walls of a room, built as
/// separate instances) see each ray through different transforms, and a ray along the seam can slip between them.
/// So each edge function may be kTriangleEdgeTolerance of their sum on the wrong side: a triangle grows by that
/// fraction of its size, closing such seams (Embree, which the CPU device uses, closes them too), and the
/// barycentrics are clamped back into the triangle (toward the side of the sum of their magnitudes).
inline constexpr float kTriangleEdgeTolerance = 1.f / 131072.f;  // 2^-17, about 7.6e-6

LOOM_HD inline bool hitTriangle(const BvhTriangle& tri, const PreparedRay& r, float tMin, float tMax, float& t,
                                float& u, float& v) {
    const glm::vec3 a = tri.p0 - r.o, b = tri.p1 - r.o, c = tri.p2 - r.o;
    const float ax = a[r.kx] - r.sx * a[r.kz], ay = a[r.ky] - r.sy * a[r.kz];
    const float bx = b[r.kx] - r.sx * b[r.kz], by = b[r.ky] - r.sy * b[r.kz];
    const float cx = c[r.kx] - r.sx * c[r.kz], cy = c[r.ky] - r.sy * c[r.kz];
    float e0 = cx * by - cy * bx;  // weight of p0
    float e1 = ax * cy - ay * cx;  // weight of p1
    float e2 = bx * ay - by * ax;  // weight of p2
    const float tol = kTriangleEdgeTolerance * (glm::abs(e0) + glm::abs(e1) + glm::abs(e2));
    if ((e0 < -tol || e1 < -tol || e2 < -tol) && (e0 > tol || e1 > tol || e2 > tol)) return false;
    if (e0 + e1 + e2 >= 0.f) {  // clamp to the side of the sum, so u, v and 1 - u - v stay within [0, 1]
        e0 = glm::max(e0, 0.f);
        e1 = glm::max(e1, 0.f);
        e2 = glm::max(e2, 0.f);
    } else {
        e0 = glm::min(e0, 0.f);
        e1 = glm::min(e1, 0.f);
        e2 = glm::min(e2, 0.f);
    }
    const float det = e0 + e1 + e2;
    if (det == 0.f || !(det == det)) return false;
    // t from the plane's equation, as Embree computes it: the sheared form (Woop's e0 az + e1 bz + e2 cz) carries
    // an error of the size of the vertices' distances, which near the origin swamps a small t.
    const glm::vec3 ng = glm::cross(tri.p1 - tri.p0, tri.p2 - tri.p0);
    const float th = glm::dot(ng, a) / glm::dot(ng, r.d);
    if (!(th > tMin && th <= tMax)) return false;
    const float inv = 1.f / det;
    t = th;
    u = e1 * inv;
    v = e2 * inv;
    return true;
}

/// Depth-first traversal of the tree at `root` of `nodes`, nearest child first, with a fixed stack. For each leaf
/// the ray's box test passes, leaf(first, count) tests its items and returns true to stop (an any-hit query);
/// tFar, which the leaf shortens at each closer hit, prunes boxes. Returns whether a leaf stopped it.
template <class Leaf>
LOOM_HD inline bool traverse(const BvhNode* nodes, uint32_t root, const PreparedRay& r, float tMin, const float& tFar,
                             Leaf& leaf) {
    uint32_t stack[kBvhStackSize];
    float enter[kBvhStackSize];
    int sp = 0;
    float t0;
    if (!hitBox(nodes[root], r, tMin, tFar, t0)) return false;
    uint32_t node = root;
    for (;;) {
        const BvhNode& n = nodes[node];
        if (n.count > 0) {
            if (leaf(n.index, n.count)) return true;
        } else {
            float tl, tr;
            const bool hl = hitBox(nodes[n.index], r, tMin, tFar, tl);
            const bool hr = hitBox(nodes[n.index + 1], r, tMin, tFar, tr);
            if (hl && hr) {
                const bool leftFirst = tl <= tr;
                if (sp < kBvhStackSize) {  // always true for Bvh's trees (kBvhMaxDepth)
                    stack[sp] = leftFirst ? n.index + 1 : n.index;
                    enter[sp++] = leftFirst ? tr : tl;
                }
                node = leftFirst ? n.index : n.index + 1;
                continue;
            }
            if (hl || hr) {
                node = hl ? n.index : n.index + 1;
                continue;
            }
        }
        // Next from the stack, skipping boxes that now lie beyond the closest hit.
        for (;;) {
            if (sp == 0) return false;
            --sp;
            if (enter[sp] <= tFar * 1.0000004f) break;
        }
        node = stack[sp];
    }
}

/// The closest hit (any: the first found, when anyHit) in (tMin, tMax] under `rules` with coverage key `key`;
/// `tri` gets the index of the hit's BvhTriangle. Back faces are not culled here.
LOOM_HD inline RayHit traceScene(const BvhView& view, glm::vec3 o, glm::vec3 d, float tMin, float tMax, uint32_t rules,
                                 uint32_t key, bool anyHit, uint32_t& tri) {
    RayHit hit;
    if (!traceable(o, d) || view.bvh.topNodes.count == 0) return hit;
    const BvhArrays& b = view.bvh;
    const bool alphaTest = (rules & kRayAlphaTest) != 0;
    float tFar = tMax;
    const PreparedRay world = prepareRay(o, d);

    struct MeshLeaf {
        const BvhView& view;
        const PreparedRay& ray;
        float tMin;
        float& tFar;
        RayHit& hit;
        uint32_t& tri;
        uint32_t instance, key;
        bool alphaTest, anyHit;
        LOOM_HD bool operator()(uint32_t first, uint32_t count) {
            bool stop = false;
            for (uint32_t i = first; i < first + count; ++i) {
                const BvhTriangle& t = view.bvh.triangles.data[i];
                float th, u, v;
                if (!hitTriangle(t, ray, tMin, tFar, th, u, v)) continue;
                if (alphaTest && !surfaceCovers(view.scene, instance, t.primitive, u, v, key)) continue;
                tFar = th;
                hit.instance = instance;
                hit.primitive = t.primitive;
                hit.u = u;
                hit.v = v;
                hit.t = th;
                tri = i;
                if (anyHit) {
                    stop = true;
                    break;
                }
            }
            return stop;
        }
    };
    struct TopLeaf {
        const BvhView& view;
        const PreparedRay& world;
        float tMin;
        float& tFar;
        RayHit& hit;
        uint32_t& tri;
        uint32_t key;
        bool alphaTest, anyHit;
        LOOM_HD bool operator()(uint32_t first, uint32_t count) {
            for (uint32_t i = first; i < first + count; ++i) {
                const uint32_t id = view.bvh.topInstances.data[i];
                const BvhInstance& inst = view.bvh.instances.data[id];
                const BvhMesh& mesh = view.bvh.meshes.data[inst.mesh];
                const PreparedRay local =
                    prepareRay(inst.toObject * world.o + inst.toObjectOffset, inst.toObject * world.d);
                MeshLeaf leaf{view, local, tMin, tFar, hit, tri, id, key, alphaTest && mesh.alphaTested != 0, anyHit};
                if (traverse(view.bvh.nodes.data, mesh.root, local, tMin, tFar, leaf)) return true;
            }
            return false;
        }
    };
    TopLeaf top{view, world, tMin, tFar, hit, tri, key, alphaTest, anyHit};
    traverse(b.topNodes.data, 0u, world, tMin, tFar, top);
    return hit;
}

/// The next float above x (toward +infinity), as std::nextafter(x, inf) for finite x.
LOOM_HD inline float nextUp(float x) {
    if (!(x == x) || x > 3.40282347e38f) return x;  // NaN, +infinity
    if (x == 0.f) return bitsToFloat(1u);
    const uint32_t bits = floatBits(x);
    return bitsToFloat(x > 0.f ? bits + 1u : bits - 1u);
}

/// RayScene's back-face rule: a single-sided material whose front (counter-clockwise) face looks away from the ray.
/// The normal is (p1 - p0) x (p2 - p0) in object space, as Embree reports it, carried by the normal matrix.
LOOM_HD inline bool culledFace(const BvhView& view, const RayHit& h, uint32_t tri, glm::vec3 d) {
    const InstanceView& inst = view.scene.instances[h.instance];
    const BvhTriangle& t = view.bvh.triangles.data[tri];
    const glm::vec3 ng = glm::cross(t.p1 - t.p0, t.p2 - t.p0);
    return !view.scene.materials[view.scene.meshes[inst.mesh].material].doubleSided &&
           !(glm::dot(inst.normalMatrix * ng, d) < 0.f);
}

}  // namespace bvhdetail

/// Closest hit of o + t d, t in (tMin, tMax], under `rules` (RayRules), drawing stochastic transparency from
/// `coverageKey`: RayScene::intersect's answer.
LOOM_HD inline RayHit bvhIntersect(const BvhView& view, glm::vec3 o, glm::vec3 d, float tMin, float tMax,
                                   uint32_t rules, uint32_t coverageKey) {
    uint32_t tri = 0;
    RayHit h = bvhdetail::traceScene(view, o, d, tMin, tMax, rules, coverageKey, false, tri);
    if ((rules & kRayCullBackFaces) && h.hit() && bvhdetail::culledFace(view, h, tri, d)) {
        // As RayScene::continuePastBackFaces: a new query from just beyond each culled face, a miss after 16.
        int layer = 1;
        for (; layer < 16; ++layer) {
            h = bvhdetail::traceScene(view, o, d, bvhdetail::nextUp(h.t), tMax, rules, coverageKey, false, tri);
            if (!h.hit() || !bvhdetail::culledFace(view, h, tri, d)) break;
        }
        if (layer == 16) return RayHit{};
    }
    return h;
}

/// bvhIntersect with the ray's own coverage key, rayCoverageKey(o, d), as RayScene::intersect.
LOOM_HD inline RayHit bvhIntersect(const BvhView& view, glm::vec3 o, glm::vec3 d, float tMin = 0.f, float tMax = 1e30f,
                                   uint32_t rules = kRayAlphaTest) {
    return bvhIntersect(view, o, d, tMin, tMax, rules, rayCoverageKey(o, d));
}

/// Whether anything lies on o + t d for t in (tMin, tMax] under `rules`: RayScene::occluded's answer. Back faces
/// are never culled (kRayCullBackFaces is ignored, as RayScene::occluded does).
LOOM_HD inline bool bvhOccluded(const BvhView& view, glm::vec3 o, glm::vec3 d, float tMin, float tMax, uint32_t rules,
                                uint32_t coverageKey) {
    uint32_t tri = 0;
    return bvhdetail::traceScene(view, o, d, tMin, tMax, rules, coverageKey, true, tri).hit();
}

/// bvhOccluded with the ray's own coverage key, rayCoverageKey(o, d), as RayScene::occluded.
LOOM_HD inline bool bvhOccluded(const BvhView& view, glm::vec3 o, glm::vec3 d, float tMin, float tMax,
                                uint32_t rules = kRayAlphaTest) {
    return bvhOccluded(view, o, d, tMin, tMax, rules, rayCoverageKey(o, d));
}

}  // namespace loom

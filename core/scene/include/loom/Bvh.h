#pragma once
// A two-level BVH over a Scene that the CPU and CUDA devices traverse alike (BvhTraversal.h): one bottom-level tree
// per mesh in object space, built once, and a top-level tree over the visible instances' world bounds, rebuilt by
// updateInstances when instances move (meshes are never rebuilt).
//
// Layout: flat arrays of plain structs (BvhArrays), none holding a pointer. Nodes are 32 bytes (bounds, child or
// first-item index, item count), children of an inner node adjacent; all meshes' trees share one node array
// (BvhMesh::root), their triangles one array in leaf order with the vertices copied. To trace on a device, copy
// each span of arrays() with one memcpy (count * sizeof(T) bytes), put the device pointers into a BvhArrays, and
// traverse a BvhView of it and a device SceneView. After updateInstances only topNodes, topInstances and instances
// change.
//
// Build: binned SAH (16 bins per axis over the centroid bounds, traversal cost 1 against 1 per item), leaves of at
// most 4 triangles (1 instance at the top), a leaf wherever its cost is not above the best split's. Below depth 32
// nodes split at the median of the widest centroid axis, so no tree is deeper than kBvhMaxDepth and the traversal's
// fixed stack (kBvhStackSize) never overflows. Single-threaded and free of any order that depends on addresses:
// the same scene gives the same bytes.
#include <cstdint>
#include <memory>
#include <vector>

#include "loom/BvhTraversal.h"

namespace loom {

class Scene;

/// The deepest a Bvh tree is (root at depth 0): below the traversal's stack size.
inline constexpr int kBvhMaxDepth = kBvhStackSize - 1;

class Bvh {
public:
    /// Builds every mesh's tree and the top-level tree of the scene's instances as they are now.
    explicit Bvh(const Scene& scene);

    /// Copies the instances' current world transforms and rebuilds the top-level tree (as RayScene::updateInstances);
    /// `scene` is the one this was built from.
    void updateInstances(const Scene& scene);

    /// The flat arrays, valid until updateInstances (top-level arrays) or destruction.
    BvhArrays arrays() const;
    /// A view for host traversal over `scene`, the view of the Scene this was built from (Scene::view()).
    BvhView view(const SceneView& scene) const { return BvhView{arrays(), scene}; }

private:
    std::vector<BvhNode> mNodes;
    std::vector<BvhTriangle> mTriangles;
    std::vector<BvhMesh> mMeshes;
    std::vector<BvhNode> mTopNodes;
    std::vector<uint32_t> mTopInstances;
    std::vector<BvhInstance> mInstances;
};

/// A scene's BVH kept across frames by a pass that traces it: built again when the scene or its meshes change
/// (Scene::meshVersion), else only its top level updated for moving instances.
class SceneBvh {
public:
    const Bvh& update(const Scene& scene);
    /// Full builds so far: with the scene's address, what a copy on a device is keyed on (the bottom level changes
    /// only with a build).
    uint64_t builds() const { return mBuilds; }

private:
    std::unique_ptr<Bvh> mBvh;
    const Scene* mScene = nullptr;
    uint64_t mMeshVersion = 0;
    uint64_t mBuilds = 0;
};

}  // namespace loom

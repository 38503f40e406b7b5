#include "loom/Bvh.h"

#include <algorithm>
#include <cfloat>

#include "loom/Error.h"
#include "loom/Scene.h"

namespace loom {

namespace {

constexpr int kBins = 16;
constexpr uint32_t kMaxLeafTriangles = 4;
constexpr uint32_t kMaxLeafInstances = 1;  // an instance costs a ray transform: the top level splits to single ones
constexpr int kSahDepth = 32;              // below it, median splits: depth <= 32 + log2(items) <= kBvhMaxDepth

/// The surface area of a box (0 for an empty one): the SAH's measure.
float surfaceArea(const Bounds& b) {
    if (!b.valid()) return 0.f;
    const glm::vec3 e = b.extent();
    return 2.f * (e.x * e.y + e.y * e.z + e.z * e.x);
}

/// What a tree is built over: the bounds of each item and its centroid.
struct Item {
    Bounds box;
    glm::vec3 centroid{0.f};
};

/// Builds one binary tree over `items` into `nodes` (appending; node indices are global), permuting `order` (item
/// ids, positions begin..end of the tree's items). A leaf's index is itemBase plus the position of its first item.
class TreeBuilder {
public:
    TreeBuilder(const std::vector<Item>& items, std::vector<uint32_t>& order, std::vector<BvhNode>& nodes,
                uint32_t itemBase, uint32_t maxLeaf)
        : mItems(items), mOrder(order), mNodes(nodes), mItemBase(itemBase), mMaxLeaf(maxLeaf) {}

    /// Builds the tree of all items; returns its root's index.
    uint32_t build() {
        const uint32_t root = uint32_t(mNodes.size());
        mNodes.emplace_back();
        split(root, 0, uint32_t(mOrder.size()), 0);
        return root;
    }

private:
    void split(uint32_t node, uint32_t begin, uint32_t end, int depth) {
        Bounds box, centroids;
        for (uint32_t i = begin; i < end; ++i) {
            box.extend(mItems[mOrder[i]].box);
            centroids.extend(mItems[mOrder[i]].centroid);
        }
        mNodes[node].lo = box.lo;
        mNodes[node].hi = box.hi;
        const uint32_t n = end - begin;
        uint32_t mid = begin;
        if (n > 1 && depth < kSahDepth) mid = sahSplit(box, centroids, begin, end);
        if (mid == begin && n > mMaxLeaf) mid = medianSplit(centroids, begin, end);
        if (mid == begin) {  // a leaf
            mNodes[node].index = mItemBase + begin;
            mNodes[node].count = n;
            return;
        }
        if (depth + 1 > kBvhMaxDepth) throw Error(Error::Info{ErrorKind::Runtime, {}, {}, "BVH too deep", {}, {}});
        const uint32_t left = uint32_t(mNodes.size());
        mNodes.emplace_back();
        mNodes.emplace_back();
        mNodes[node].index = left;
        mNodes[node].count = 0;
        split(left, begin, mid, depth + 1);
        split(left + 1, mid, end, depth + 1);
    }

    /// The best binned-SAH split of items begin..end, partitioned in place: the first item of the right child, or
    /// `begin` where a leaf costs no more (and may be one: n <= maxLeaf) or no split separates the centroids.
    uint32_t sahSplit(const Bounds& box, const Bounds& centroids, uint32_t begin, uint32_t end) {
        const uint32_t n = end - begin;
        float bestCost = FLT_MAX;
        int bestAxis = -1, bestBin = 0;
        for (int axis = 0; axis < 3; ++axis) {
            const float extent = centroids.hi[axis] - centroids.lo[axis];
            if (!(extent > 0.f)) continue;
            Bounds bins[kBins];
            uint32_t counts[kBins] = {};
            for (uint32_t i = begin; i < end; ++i) {
                const Item& it = mItems[mOrder[i]];
                const int b = binOf(it.centroid[axis], centroids.lo[axis], extent);
                bins[b].extend(it.box);
                ++counts[b];
            }
            // Sweep from the right: areas and counts of bins b.. , then from the left for each split plane.
            float rightArea[kBins];
            uint32_t rightCount[kBins];
            Bounds acc;
            uint32_t cnt = 0;
            for (int b = kBins - 1; b > 0; --b) {
                acc.extend(bins[b]);
                cnt += counts[b];
                rightArea[b] = surfaceArea(acc);
                rightCount[b] = cnt;
            }
            acc = Bounds{};
            cnt = 0;
            for (int b = 1; b < kBins; ++b) {
                acc.extend(bins[b - 1]);
                cnt += counts[b - 1];
                if (cnt == 0 || rightCount[b] == 0) continue;
                const float cost = surfaceArea(acc) * float(cnt) + rightArea[b] * float(rightCount[b]);
                if (cost < bestCost) {
                    bestCost = cost;
                    bestAxis = axis;
                    bestBin = b;
                }
            }
        }
        if (bestAxis < 0) return begin;
        // Cost 1 per traversal step and per item: a split costs 1 + (A_L N_L + A_R N_R) / A, a leaf n.
        const float parentArea = surfaceArea(box);
        const float splitCost = parentArea > 0.f ? 1.f + bestCost / parentArea : float(n);
        if (n <= mMaxLeaf && float(n) <= splitCost) return begin;
        const float lo = centroids.lo[bestAxis], extent = centroids.hi[bestAxis] - lo;
        const auto first = mOrder.begin() + begin;
        const auto it = std::stable_partition(first, mOrder.begin() + end, [&](uint32_t id) {
            return binOf(mItems[id].centroid[bestAxis], lo, extent) < bestBin;
        });
        return uint32_t(it - mOrder.begin());
    }

    /// Splits items begin..end in halves by their centroids along the widest axis (ties by item id, so the result is
    /// one order, whatever the library's nth_element does with equal keys).
    uint32_t medianSplit(const Bounds& centroids, uint32_t begin, uint32_t end) {
        const glm::vec3 e = centroids.hi - centroids.lo;
        const int axis = e.x >= e.y ? (e.x >= e.z ? 0 : 2) : (e.y >= e.z ? 1 : 2);
        const uint32_t mid = begin + (end - begin) / 2;
        std::nth_element(mOrder.begin() + begin, mOrder.begin() + mid, mOrder.begin() + end,
                         [&](uint32_t a, uint32_t b) {
                             const float ca = mItems[a].centroid[axis], cb = mItems[b].centroid[axis];
                             return ca < cb || (ca == cb && a < b);
                         });
        return mid;
    }

    static int binOf(float c, float lo, float extent) {
        const int b = int((c - lo) * (float(kBins) / extent));
        return b < 0 ? 0 : (b >= kBins ? kBins - 1 : b);
    }

    const std::vector<Item>& mItems;
    std::vector<uint32_t>& mOrder;
    std::vector<BvhNode>& mNodes;
    uint32_t mItemBase, mMaxLeaf;
};

std::vector<uint32_t> identityOrder(size_t n) {
    std::vector<uint32_t> order(n);
    for (size_t i = 0; i < n; ++i) order[i] = uint32_t(i);
    return order;
}

}  // namespace

Bvh::Bvh(const Scene& scene) {
    for (const Mesh& mesh : scene.meshes) {
        BvhMesh m;
        m.alphaTested =
            mesh.material < scene.materials.size() && scene.materials[mesh.material].alphaMode != AlphaMode::Opaque;
        // Triangles of zero area (a zero normal in float, as Embree computes it) are left out: no ray hits them,
        // while the sheared edge functions of the watertight test need not all be exactly zero for them.
        std::vector<Item> items;
        std::vector<uint32_t> prims;
        for (uint32_t t = 0; t < mesh.triangleCount(); ++t) {
            const glm::vec3 p0 = mesh.positions[mesh.indices[3 * t]], p1 = mesh.positions[mesh.indices[3 * t + 1]],
                            p2 = mesh.positions[mesh.indices[3 * t + 2]];
            if (glm::cross(p1 - p0, p2 - p0) == glm::vec3(0.f)) continue;
            Item it;
            it.box.extend(p0);
            it.box.extend(p1);
            it.box.extend(p2);
            it.centroid = it.box.center();
            items.push_back(it);
            prims.push_back(t);
        }
        if (!items.empty()) {
            std::vector<uint32_t> order = identityOrder(items.size());
            const uint32_t base = uint32_t(mTriangles.size());
            m.root = TreeBuilder(items, order, mNodes, base, kMaxLeafTriangles).build();
            for (uint32_t k : order) {
                const uint32_t t = prims[k];
                BvhTriangle tri;
                tri.p0 = mesh.positions[mesh.indices[3 * t]];
                tri.p1 = mesh.positions[mesh.indices[3 * t + 1]];
                tri.p2 = mesh.positions[mesh.indices[3 * t + 2]];
                tri.primitive = t;
                mTriangles.push_back(tri);
            }
        }
        mMeshes.push_back(m);
    }
    updateInstances(scene);
}

void Bvh::updateInstances(const Scene& scene) {
    mInstances.assign(scene.instances.size(), BvhInstance{});
    std::vector<Item> items;
    std::vector<uint32_t> ids;
    for (size_t i = 0; i < scene.instances.size(); ++i) {
        const Instance& inst = scene.instances[i];
        BvhInstance& b = mInstances[i];
        b.mesh = inst.mesh;
        // As RayScene: a hidden instance (no inverse within range) is left out of the top level.
        if (inst.mesh >= mMeshes.size() || mMeshes[inst.mesh].root == kInvalidId || !inst.visible()) continue;
        // The inverse in double, rounded once: rays enter object space with the least error this layout allows.
        const glm::dmat3 inverse = glm::inverse(glm::dmat3(glm::mat3(inst.world)));
        b.toObject = glm::mat3(inverse);
        b.toObjectOffset = glm::vec3(-(inverse * glm::dvec3(glm::vec3(inst.world[3]))));
        // World bounds: the mesh's box corners carried by the transform, widened by a little more than the rounding
        // of the carry and of the ray's inverse carry, so the top level never loses a hit at an instance's face.
        const BvhNode& root = mNodes[mMeshes[inst.mesh].root];
        Item it;
        for (int c = 0; c < 8; ++c) {
            const glm::vec3 p((c & 1) ? root.hi.x : root.lo.x, (c & 2) ? root.hi.y : root.lo.y,
                              (c & 4) ? root.hi.z : root.lo.z);
            it.box.extend(glm::vec3(inst.world * glm::vec4(p, 1.f)));
        }
        const glm::vec3 mag = glm::max(glm::abs(it.box.lo), glm::abs(it.box.hi));
        const float pad = 1e-5f * std::max({mag.x, mag.y, mag.z, FLT_MIN});
        it.box.lo -= pad;
        it.box.hi += pad;
        it.centroid = it.box.center();
        items.push_back(it);
        ids.push_back(uint32_t(i));
    }
    mTopNodes.clear();
    mTopInstances.clear();
    if (items.empty()) return;
    std::vector<uint32_t> order = identityOrder(items.size());
    TreeBuilder(items, order, mTopNodes, 0, kMaxLeafInstances).build();
    for (uint32_t k : order) mTopInstances.push_back(ids[k]);
}

BvhArrays Bvh::arrays() const {
    BvhArrays a;
    a.nodes = {mNodes.data(), uint32_t(mNodes.size())};
    a.triangles = {mTriangles.data(), uint32_t(mTriangles.size())};
    a.meshes = {mMeshes.data(), uint32_t(mMeshes.size())};
    a.topNodes = {mTopNodes.data(), uint32_t(mTopNodes.size())};
    a.topInstances = {mTopInstances.data(), uint32_t(mTopInstances.size())};
    a.instances = {mInstances.data(), uint32_t(mInstances.size())};
    return a;
}

const Bvh& SceneBvh::update(const Scene& scene) {
    if (!mBvh || mScene != &scene || mMeshVersion != scene.meshVersion()) {
        mBvh = std::make_unique<Bvh>(scene);
        mScene = &scene;
        mMeshVersion = scene.meshVersion();
        ++mBuilds;
    } else {
        mBvh->updateInstances(scene);  // moving instances rebuild the top level only
    }
    return *mBvh;
}

}  // namespace loom

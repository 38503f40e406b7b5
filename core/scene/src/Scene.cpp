// Scene: building instances from the node hierarchy, per-frame animation and
// camera paths, animation sampling, environment maps, and the plain view that
// kernels read. Loading glTF files lives in SceneLoader.cpp.
#include "loom/Scene.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <numbers>

#include "loom/Error.h"
#include "loom/ImageIO.h"
#include "loom/RayScene.h"

namespace loom {

// ---------------------------------------------------------------------------
// Nodes and animation sampling

glm::mat4 Node::local() const {
    if (hasMatrix) return matrix;
    return glm::translate(glm::mat4(1.f), translation) * glm::mat4_cast(rotation) * glm::scale(glm::mat4(1.f), scale);
}

namespace {

// Rotations are stored as vec4 (x, y, z, w) like glTF; glm's quat constructor takes (w, x, y, z).
glm::quat toQuat(const glm::vec4& v) {
    return glm::quat(v.w, v.x, v.y, v.z);
}
glm::vec4 fromQuat(const glm::quat& q) {
    return glm::vec4(q.x, q.y, q.z, q.w);
}

glm::vec4 normalizedRotation(const glm::vec4& v) {
    const float len = glm::length(v);
    // A zero quaternion (broken data) has no orientation; identity is the only safe answer.
    return len > 0.f && std::isfinite(len) ? v / len : glm::vec4(0.f, 0.f, 0.f, 1.f);
}

glm::vec4 neutralValue(AnimPath path) {
    switch (path) {
        case AnimPath::Rotation:
            return glm::vec4(0.f, 0.f, 0.f, 1.f);
        case AnimPath::Scale:
            return glm::vec4(1.f, 1.f, 1.f, 0.f);
        default:
            break;
    }
    return glm::vec4(0.f);
}

}  // namespace

glm::vec4 AnimationSampler::sample(float t, AnimPath path) const {
    const bool cubic = interpolation == Interpolation::CubicSpline;
    const size_t keys = times.size();
    if (keys == 0 || values.size() < keys * (cubic ? 3 : 1)) return neutralValue(path);

    // Cubic splines store (in-tangent, value, out-tangent) per key.
    auto keyValue = [&](size_t k) { return cubic ? values[3 * k + 1] : values[k]; };
    auto finish = [&](const glm::vec4& v) { return path == AnimPath::Rotation ? normalizedRotation(v) : v; };

    // Outside the key range the animation holds its first / last pose (also for a NaN time).
    if (!(t > times.front())) return finish(keyValue(0));
    if (t >= times.back()) return finish(keyValue(keys - 1));

    const size_t k1 = size_t(std::upper_bound(times.begin(), times.end(), t) - times.begin());
    const size_t k0 = k1 - 1;
    const float td = times[k1] - times[k0];
    const float s = td > 0.f ? (t - times[k0]) / td : 0.f;

    switch (interpolation) {
        case Interpolation::Step:
            return finish(keyValue(k0));
        case Interpolation::Linear:
            if (path == AnimPath::Rotation) {
                // glm::slerp takes the shorter arc (it negates one end when their dot product is negative).
                const glm::quat q0 = toQuat(normalizedRotation(keyValue(k0)));
                const glm::quat q1 = toQuat(normalizedRotation(keyValue(k1)));
                return normalizedRotation(fromQuat(glm::slerp(q0, q1, s)));
            }
            return glm::mix(keyValue(k0), keyValue(k1), s);
        case Interpolation::CubicSpline: {
            // glTF 2.0, Appendix C: Hermite spline whose tangents are scaled by the key interval.
            const float s2 = s * s, s3 = s2 * s;
            const glm::vec4 p0 = values[3 * k0 + 1];
            const glm::vec4 m0 = td * values[3 * k0 + 2];  // out-tangent of key k0
            const glm::vec4 p1 = values[3 * k1 + 1];
            const glm::vec4 m1 = td * values[3 * k1 + 0];  // in-tangent of key k1
            return finish((2.f * s3 - 3.f * s2 + 1.f) * p0 + (s3 - 2.f * s2 + s) * m0 + (-2.f * s3 + 3.f * s2) * p1 +
                          (s3 - s2) * m1);
        }
    }
    return finish(keyValue(k0));
}

float Animation::duration() const {
    // Only samplers that drive a channel count: a sampler nobody uses (e.g. of an ignored morph-weight
    // channel) moves nothing.
    float d = 0.f;
    for (const AnimationChannel& ch : channels)
        if (ch.sampler < samplers.size() && !samplers[ch.sampler].times.empty())
            d = std::max(d, samplers[ch.sampler].times.back());
    return d;
}

// ---------------------------------------------------------------------------
// Scene

namespace {

/// Writes every animation's value at time t into its target: the nodes' TRS, the materials' emission and the
/// punctual lights' intensity and colour. All animations play together, each clamped to its own key range.
void applyAnimations(const std::vector<Animation>& animations, std::vector<Node>& nodes,
                     std::vector<Material>& materials, std::vector<Light>& lights, float t) {
    bool emissionAnimated = false;
    for (const Animation& anim : animations) {
        for (const AnimationChannel& ch : anim.channels) {
            if (ch.sampler >= anim.samplers.size()) continue;
            if (animatesLight(ch.path)) {
                // A cubic spline may overshoot below 0 between keys the loader checked; light is never negative.
                const glm::vec4 v = glm::max(anim.samplers[ch.sampler].sample(t, ch.path), glm::vec4(0.f));
                const bool material = ch.path == AnimPath::EmissiveColor || ch.path == AnimPath::EmissiveStrength;
                if (material && ch.target >= 0 && size_t(ch.target) < materials.size()) {
                    Material& m = materials[size_t(ch.target)];
                    if (ch.path == AnimPath::EmissiveColor)
                        m.emissiveColor = glm::vec3(v);
                    else
                        m.emissiveStrength = v.x;
                    emissionAnimated = true;
                }
                // Every node that places the file's light shows the same light.
                for (Light& light : lights) {
                    if (material || light.source != ch.target) continue;
                    if (ch.path == AnimPath::LightIntensity)
                        light.intensity = v.x;
                    else
                        light.color = glm::vec3(v);
                }
                continue;
            }
            if (ch.node < 0 || size_t(ch.node) >= nodes.size()) continue;
            Node& node = nodes[size_t(ch.node)];
            if (node.hasMatrix) continue;  // glTF forbids animating matrix nodes; the loader warned
            const glm::vec4 v = anim.samplers[ch.sampler].sample(t, ch.path);
            switch (ch.path) {
                case AnimPath::Translation:
                    node.translation = glm::vec3(v);
                    break;
                case AnimPath::Rotation:
                    node.rotation = toQuat(v);
                    break;
                case AnimPath::Scale:
                    node.scale = glm::vec3(v);
                    break;
                default:
                    break;
            }
        }
    }
    if (!emissionAnimated) return;
    // Only materials an animation targets are recomputed: the others keep emissiveFactor as loaded or set in code.
    for (const Animation& anim : animations)
        for (const AnimationChannel& ch : anim.channels)
            if ((ch.path == AnimPath::EmissiveColor || ch.path == AnimPath::EmissiveStrength) && ch.target >= 0 &&
                size_t(ch.target) < materials.size()) {
                Material& m = materials[size_t(ch.target)];
                m.emissiveFactor = m.emissiveColor * m.emissiveStrength;
            }
}

/// Whether an animation channel drives material `index`'s emission.
bool emissionAnimated(const std::vector<Animation>& animations, size_t index) {
    for (const Animation& anim : animations)
        for (const AnimationChannel& ch : anim.channels)
            if ((ch.path == AnimPath::EmissiveColor || ch.path == AnimPath::EmissiveStrength) &&
                ch.target == int(index))
                return true;
    return false;
}

/// The first node that carries camera `cam`, or -1.
int cameraNode(const std::vector<Node>& nodes, int cam) {
    for (size_t i = 0; i < nodes.size(); ++i)
        if (nodes[i].camera == cam) return int(i);
    return -1;
}

/// A camera's pose without the node's scale: cameras are rigid by convention
/// (view = inverse(world) must not distort). The axes are normalised; when
/// they are then not (nearly) orthonormal (shear, axes scaled to 0 or parallel,
/// a non-finite entry) they are rebuilt from the first two by Gram-Schmidt, and
/// failing that are the identity's. The bottom row is always (0, 0, 0, 1) (a
/// projective row would make the view singular), and a position that is not
/// finite becomes the origin, so the camera's rays and its view stay valid.
glm::mat4 rigid(const glm::mat4& m) {
    const auto finite = [](const glm::vec3& v) {
        return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
    };
    // v / |v|; where a square overflows or underflows, scaled by its largest component first; NaN for a zero or
    // non-finite v.
    const auto unit = [](glm::vec3 v) {
        const float length = glm::length(v);
        if (length > 0.f && std::isfinite(length)) return v / length;
        const float largest = std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)});
        if (!(largest > 0.f) || !std::isfinite(largest)) return glm::vec3(std::numeric_limits<float>::quiet_NaN());
        v /= largest;
        return v / glm::length(v);
    };
    glm::vec3 axis[3] = {unit(glm::vec3(m[0])), unit(glm::vec3(m[1])), unit(glm::vec3(m[2]))};
    const float tolerance = 1e-3f;
    bool orthonormal = finite(axis[0]) && finite(axis[1]) && finite(axis[2]);
    for (int a = 0; a < 3 && orthonormal; ++a)
        orthonormal = std::fabs(glm::dot(axis[a], axis[(a + 1) % 3])) < tolerance;
    if (orthonormal)
        orthonormal = std::fabs(std::fabs(glm::determinant(glm::mat3(axis[0], axis[1], axis[2]))) - 1.f) < tolerance;
    if (!orthonormal) {
        // Gram-Schmidt on the first two axes when they are far enough from parallel; else the identity's axes.
        const glm::vec3 x = axis[0], y = axis[1];
        const glm::vec3 rest = y - glm::dot(y, x) * x;
        if (finite(x) && finite(y) && glm::length(rest) > tolerance) {
            axis[1] = unit(rest);
            axis[2] = glm::cross(x, axis[1]);
        } else {
            axis[0] = glm::vec3(1.f, 0.f, 0.f);
            axis[1] = glm::vec3(0.f, 1.f, 0.f);
            axis[2] = glm::vec3(0.f, 0.f, 1.f);
        }
    }
    glm::mat4 r(1.f);
    for (int c = 0; c < 3; ++c) r[c] = glm::vec4(axis[c], 0.f);
    const glm::vec3 t(m[3]);
    if (finite(t)) r[3] = glm::vec4(t, 1.f);
    return r;
}

std::string nodeLabel(const std::vector<Node>& nodes, size_t i) {
    std::string label = "nodes[" + std::to_string(i) + "]";
    if (!nodes[i].name.empty()) label += " '" + nodes[i].name + "'";
    return label;
}

/// Visits every node under a parentless one, parents before their children (depth first). Nodes on or under a
/// cycle are not visited.
template <class Fn>
void visitParentsFirst(const std::vector<Node>& nodes, Fn&& visit) {
    std::vector<int> stack;
    for (size_t i = 0; i < nodes.size(); ++i)
        if (nodes[i].parent < 0) stack.push_back(int(i));
    while (!stack.empty()) {
        const int n = stack.back();
        stack.pop_back();
        visit(size_t(n));
        for (int c : nodes[size_t(n)].children) stack.push_back(c);
    }
}

}  // namespace

Scene::Scene() = default;
Scene::~Scene() = default;

bool Instance::visible() const {
    const glm::mat3 m(world);
    const float det = glm::determinant(m);
    if (!(std::fabs(det) > 0.f) || !std::isfinite(det)) return false;
    // Rays enter the instance through the inverse: with the translation it must keep them in Embree's range
    // (kWorldLimit).
    const glm::mat3 inv = glm::inverse(m);
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r)
            if (!(std::fabs(inv[c][r]) <= 1e9f)) return false;
    for (int r = 0; r < 3; ++r)
        if (!(std::fabs(world[3][r]) <= kWorldLimit)) return false;
    return true;
}

void Scene::updateWorldTransforms() {
    mNodeWorld.assign(nodes.size(), glm::mat4(1.f));
    visitParentsFirst(nodes, [&](size_t n) {
        const Node& node = nodes[n];
        mNodeWorld[n] = node.parent >= 0 ? mNodeWorld[size_t(node.parent)] * node.local() : node.local();
    });
}

/// Parents from the children lists, checked to form a forest (a node with two parents, or a cycle, would make
/// world transforms ambiguous), and the roots when the scene names none.
void Scene::linkHierarchy() {
    // Parents follow from the children lists; a node with two parents or a cycle
    // would make world transforms ambiguous, so both are rejected.
    for (Node& n : nodes) n.parent = -1;
    for (size_t i = 0; i < nodes.size(); ++i) {
        for (int c : nodes[i].children) {
            if (c < 0 || size_t(c) >= nodes.size())
                throwBadInput(nodeLabel(nodes, i), "child index " + std::to_string(c) + " is out of range",
                              "an index below " + std::to_string(nodes.size()));
            if (nodes[size_t(c)].parent >= 0 || size_t(c) == i)
                throwBadInput(nodeLabel(nodes, size_t(c)), "node is the child of more than one node (or of itself)",
                              "a tree: every node has at most one parent");
            nodes[size_t(c)].parent = int(i);
        }
    }
    {
        // With unique parents, a node that no parentless node reaches lies on or under a cycle.
        std::vector<bool> reached(nodes.size(), false);
        visitParentsFirst(nodes, [&](size_t n) { reached[n] = true; });
        for (size_t i = 0; i < nodes.size(); ++i)
            if (!reached[i])
                throwBadInput(nodeLabel(nodes, i), "node is part of a cycle in the hierarchy",
                              "a tree: no node is its own ancestor");
    }
    if (roots.empty())
        for (size_t i = 0; i < nodes.size(); ++i)
            if (nodes[i].parent < 0) roots.push_back(int(i));
}

/// The render camera: the chosen glTF camera when it hangs in the hierarchy, else one framing the rest bounds.
void Scene::chooseCamera() {
    if (activeCamera < 0 || size_t(activeCamera) >= cameras.size() || cameraNode(nodes, activeCamera) < 0) {
        activeCamera = -1;
        for (size_t c = 0; c < cameras.size(); ++c) {
            if (cameraNode(nodes, int(c)) >= 0) {
                activeCamera = int(c);
                break;
            }
        }
    }
    mCameraAnimated = false;
    if (activeCamera >= 0) {
        camera = cameras[size_t(activeCamera)];
        // Animated when a channel targets the camera's node or any of its ancestors.
        for (int n = cameraNode(nodes, activeCamera); n >= 0 && !mCameraAnimated; n = nodes[size_t(n)].parent)
            for (const Animation& a : animations)
                for (const AnimationChannel& ch : a.channels)
                    if (ch.node == n) mCameraAnimated = true;
    } else {
        camera = Camera{};
        camera.name = "default";
        const glm::vec3 center = mRestBounds.valid() ? mRestBounds.center() : glm::vec3(0.f);
        const float radius = mRestBounds.valid() ? std::max(0.5f * glm::length(mRestBounds.extent()), 1e-3f) : 1.f;
        // The bounding sphere fits the vertical field of view exactly.
        const float distance = radius / std::sin(0.5f * camera.fovY);
        camera.world = glm::translate(glm::mat4(1.f), center + glm::vec3(0.f, 0.f, distance));
        camera.nearZ = 1e-2f * radius;
        camera.farZ = 10.f * (distance + radius);
    }
    camera.prevWorld = camera.world;
    mCameraBase = camera.world;
}

void Scene::finalize() {
    linkHierarchy();

    for (size_t m = 0; m < meshes.size(); ++m) {
        Mesh& mesh = meshes[m];
        mesh.bounds = Bounds{};
        for (const glm::vec3& p : mesh.positions) mesh.bounds.extend(p);
        if (mesh.material >= materials.size())
            throwBadInput("meshes[" + std::to_string(m) + "] '" + mesh.name + "'",
                          "material " + std::to_string(mesh.material) + " is out of range",
                          "an index below " + std::to_string(materials.size()));
    }

    // One instance per (node, primitive), depth-first from the roots in file order.
    instances.clear();
    {
        std::vector<int> stack(roots.rbegin(), roots.rend());
        while (!stack.empty()) {
            const int n = stack.back();
            stack.pop_back();
            if (n < 0 || size_t(n) >= nodes.size())
                throwBadInput("roots", "node index " + std::to_string(n) + " is out of range",
                              "an index below " + std::to_string(nodes.size()));
            const Node& node = nodes[size_t(n)];
            for (uint32_t m : node.meshes) {
                if (m >= meshes.size())
                    throwBadInput(nodeLabel(nodes, size_t(n)), "mesh " + std::to_string(m) + " is out of range",
                                  "an index below " + std::to_string(meshes.size()));
                instances.push_back(Instance{uint32_t(n), m, glm::mat4(1.f), glm::mat4(1.f)});
            }
            for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) stack.push_back(*it);
        }
    }

    // The rest pose is the pose at time 0, so bounds and the default camera see the first frame.
    applyAnimations(animations, nodes, materials, lights, 0.f);
    updateWorldTransforms();
    for (Instance& inst : instances) inst.world = inst.prevWorld = mNodeWorld[inst.node];
    for (size_t i = 0; i < nodes.size(); ++i) {
        const int c = nodes[i].camera;
        if (c >= 0 && size_t(c) < cameras.size())
            cameras[size_t(c)].world = cameras[size_t(c)].prevWorld = rigid(mNodeWorld[i]);
    }
    mRestBounds = bounds();

    emissiveTriangles.clear();
    for (size_t i = 0; i < instances.size(); ++i) {
        const Mesh& mesh = meshes[instances[i].mesh];
        if (!materials[mesh.material].isEmissive() && !emissionAnimated(animations, mesh.material)) continue;
        for (uint32_t t = 0; t < mesh.triangleCount(); ++t) emissiveTriangles.push_back({uint32_t(i), t});
    }

    chooseCamera();

    mRayScene = std::make_unique<RayScene>(*this);
    mUpdated = false;
    mLightingChanged = false;
    mLightState = lightState();
    computeFeatures();
    ++mGeometryVersion;
    ++mMeshVersion;
    rebuildView();
}

void Scene::update(double time) {
    applyAnimations(animations, nodes, materials, lights, float(time));
    updateWorldTransforms();
    std::vector<float> light = lightState();
    mLightingChanged = mUpdated && light != mLightState;
    mLightState = std::move(light);

    // Whether an instance's transform (now or last frame's) changed: only then are the ray-tracing instances
    // committed again and the instances' view rebuilt, so a static scene does no per-frame rebuild work.
    bool moved = !mUpdated;
    for (Instance& inst : instances) {
        const glm::mat4& world = mNodeWorld[inst.node];
        const glm::mat4 prev = mUpdated ? inst.world : world;
        moved = moved || prev != inst.prevWorld || world != inst.world;
        inst.prevWorld = prev;
        inst.world = world;
    }
    for (Light& light : lights) {
        if (light.node < 0 || size_t(light.node) >= nodes.size()) continue;
        const glm::mat4& w = mNodeWorld[size_t(light.node)];
        light.position = glm::vec3(w[3]);
        // Punctual lights shine down their node's local -Z.
        const glm::vec3 dir = glm::vec3(w * glm::vec4(0.f, 0.f, -1.f, 0.f));
        if (glm::dot(dir, dir) > 0.f) light.direction = glm::normalize(dir);
    }
    for (size_t i = 0; i < nodes.size(); ++i) {
        const int c = nodes[i].camera;
        if (c < 0 || size_t(c) >= cameras.size()) continue;
        Camera& cam = cameras[size_t(c)];
        const glm::mat4 w = rigid(mNodeWorld[i]);
        cam.prevWorld = mUpdated ? cam.world : w;
        cam.world = w;
    }

    glm::mat4 camWorld = mCameraBase;
    if (mCameraAnimated && activeCamera >= 0) {
        camWorld = cameras[size_t(activeCamera)].world;
    } else if (cameraPath.kind != CameraPathKind::Static) {
        const glm::vec3 center = mRestBounds.valid() ? mRestBounds.center() : glm::vec3(0.f);
        // Wrap the angle in double so long sequences keep float precision.
        const double phase = std::fmod(double(cameraPath.speed) * time, 2.0 * std::numbers::pi);
        if (cameraPath.kind == CameraPathKind::Orbit) {
            const glm::mat4 orbit = glm::translate(glm::mat4(1.f), center) *
                                    glm::rotate(glm::mat4(1.f), float(phase), glm::vec3(0.f, 1.f, 0.f)) *
                                    glm::translate(glm::mat4(1.f), -center);
            camWorld = orbit * mCameraBase;
        } else {
            float distance = glm::length(glm::vec3(mCameraBase[3]) - center);
            if (!(distance > 0.f)) distance = mRestBounds.valid() ? glm::length(mRestBounds.extent()) : 1.f;
            // Dolly along the view direction, strafe along the camera's right axis.
            const glm::vec3 axis = cameraPath.kind == CameraPathKind::Dolly
                                       ? -glm::normalize(glm::vec3(mCameraBase[2]))
                                       : glm::normalize(glm::vec3(mCameraBase[0]));
            const float offset = cameraPath.amount * distance * float(std::sin(phase));
            camWorld = glm::translate(glm::mat4(1.f), axis * offset) * mCameraBase;
        }
    }
    camera.prevWorld = mUpdated ? camera.world : camWorld;
    camera.world = camWorld;

    if (mRayScene && moved) mRayScene->updateInstances(*this);
    if (moved) ++mGeometryVersion;
    mUpdated = true;
    updateDynamicFeatures();
    rebuildView(moved);
}

void Scene::cutMotion() {
    mLightingChanged = false;
    for (Instance& inst : instances) inst.prevWorld = inst.world;
    for (Camera& cam : cameras) cam.prevWorld = cam.world;
    camera.cut();
    rebuildView();
}

void Scene::setCameraPose(const glm::mat4& world) {
    mCameraBase = world;
    camera.world = world;
}

Bounds Scene::bounds() const {
    Bounds b;
    for (const Instance& inst : instances) {
        const Bounds& mb = meshes[inst.mesh].bounds;
        if (!mb.valid()) continue;
        for (int corner = 0; corner < 8; ++corner) {
            const glm::vec3 p((corner & 1) ? mb.hi.x : mb.lo.x, (corner & 2) ? mb.hi.y : mb.lo.y,
                              (corner & 4) ? mb.hi.z : mb.lo.z);
            b.extend(glm::vec3(inst.world * glm::vec4(p, 1.f)));
        }
    }
    return b;
}

float Scene::animationLength() const {
    float len = 0.f;
    for (const Animation& a : animations) len = std::max(len, a.duration());
    return len;
}

size_t Scene::triangleCount() const {
    size_t n = 0;
    for (const Instance& inst : instances) n += meshes[inst.mesh].triangleCount();
    return n;
}

bool Scene::hasMotion() const {
    if (cameraPath.kind != CameraPathKind::Static) return true;
    for (const Animation& a : animations)
        if (!a.channels.empty()) return true;
    return false;
}

std::vector<float> Scene::lightState() const {
    std::vector<float> state;
    const bool animated = std::any_of(animations.begin(), animations.end(), [](const Animation& a) {
        return std::any_of(a.channels.begin(), a.channels.end(),
                           [](const AnimationChannel& ch) { return animatesLight(ch.path); });
    });
    if (!animated) return state;
    for (const Material& m : materials)
        state.insert(state.end(), {m.emissiveFactor.x, m.emissiveFactor.y, m.emissiveFactor.z});
    for (const Light& l : lights) state.insert(state.end(), {l.color.x, l.color.y, l.color.z, l.intensity});
    return state;
}

std::vector<float> Scene::lightStepTimes() const {
    std::vector<float> steps;
    for (const Animation& anim : animations) {
        for (const AnimationChannel& ch : anim.channels) {
            if (!animatesLight(ch.path) || ch.sampler >= anim.samplers.size()) continue;
            const AnimationSampler& s = anim.samplers[ch.sampler];
            const bool cubic = s.interpolation == Interpolation::CubicSpline;
            if (s.values.size() < s.times.size() * (cubic ? 3 : 1)) continue;
            const auto value = [&](size_t k) { return cubic ? s.values[3 * k + 1] : s.values[k]; };
            for (size_t k = 1; k < s.times.size(); ++k) {
                const bool jumps = s.interpolation == Interpolation::Step || s.times[k] == s.times[k - 1];
                if (jumps && value(k) != value(k - 1)) steps.push_back(s.times[k]);
            }
        }
    }
    std::sort(steps.begin(), steps.end());
    steps.erase(std::unique(steps.begin(), steps.end()), steps.end());
    return steps;
}

bool Scene::emitsLight() const {
    const auto notBlack = [](glm::vec3 c) { return c.x > 0.f || c.y > 0.f || c.z > 0.f; };
    for (const Instance& inst : instances) {
        const Material& m = materials[meshes[inst.mesh].material];
        if (!m.isEmissive() || meshes[inst.mesh].triangleCount() == 0) continue;
        if (m.emissiveTexture.image < 0) return true;
        for (const glm::u8vec4& t : images[size_t(m.emissiveTexture.image)].texels)
            if (t.r || t.g || t.b) return true;
    }
    for (const Light& l : lights)
        if (l.intensity > 0.f && notBlack(l.color)) return true;
    if (environment.intensity <= 0.f) return false;
    if (environment.isConstant()) return notBlack(environment.color);
    return std::any_of(environment.texels.begin(), environment.texels.end(), notBlack);
}

void Scene::loadEnvironmentMap(const std::filesystem::path& path) {
    const std::string name = path.string();
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
        throwBadInput("environment map", "file not found", "an equirectangular .hdr or .exr image", "check the path",
                      name);
    std::string ext = path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    const Texture tex = ext == ".exr" ? readImage(path) : readRadianceHdr(path);
    if (tex.format() != Format::RGBA32F)
        throwBadInput("environment map", "the image holds integer or 8-bit channels, not radiance",
                      "an RGB(A) float or half EXR", {}, name);
    const uint32_t width = tex.width(), height = tex.height();
    std::vector<glm::vec3> texels(size_t(width) * height);
    const auto view = tex.view<glm::vec4>();
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t x = 0; x < width; ++x) texels[size_t(y) * width + x] = glm::vec3(view.at(x, y));
    // Light sampling builds a distribution from these values: a NaN, Inf or negative texel would poison it.
    size_t fixed = 0;
    for (glm::vec3& t : texels) {
        for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(t[c]) || t[c] < 0.f) {
                t[c] = 0.f;
                ++fixed;
            }
        }
    }
    if (fixed > 0) {
        std::string msg = name + ": environment map has " + std::to_string(fixed) +
                          " NaN, infinite or negative values; they were set to 0";
        spdlog::warn("{}", msg);
        warnings.push_back(std::move(msg));
    }
    environment.width = width;
    environment.height = height;
    environment.texels = std::move(texels);
    updateDynamicFeatures();
}

void Scene::computeFeatures() {
    SceneFeatures f;
    f.diffuseOnly = true;
    for (const Material& m : materials) {
        f.textures = f.textures || m.baseColorTexture.image >= 0 || m.metallicRoughnessTexture.image >= 0 ||
                     m.normalTexture.image >= 0 || m.emissiveTexture.image >= 0;
        f.normalMaps = f.normalMaps || m.normalTexture.image >= 0;
        f.alphaTested = f.alphaTested || m.alphaMode != AlphaMode::Opaque;
        // metallic = clamp(metallicFactor * texture) is 0 for a factor of 0; specularFactor 0 makes both the
        // dielectric's f0 (dielectricF0) and its f90 zero.
        f.diffuseOnly = f.diffuseOnly && m.metallicFactor == 0.f && m.specularFactor == 0.f;
    }
    f.emissiveTriangles = !emissiveTriangles.empty();
    f.punctualLights = !lights.empty();
    for (const Animation& a : animations)
        for (const AnimationChannel& ch : a.channels) {
            if (ch.sampler >= a.samplers.size()) continue;
            if (animatesLight(ch.path))
                f.animatedLights = true;
            else if (ch.node >= 0 && size_t(ch.node) < nodes.size() && !nodes[size_t(ch.node)].hasMatrix)
                f.animatedNodes = true;
        }
    mFeatures = f;
    updateDynamicFeatures();
}

/// The flags tools may change after loading without finalize(): the environment and the camera path.
void Scene::updateDynamicFeatures() {
    SceneFeatures& f = mFeatures;
    if (environment.isConstant())
        f.environment = environment.color * environment.intensity == glm::vec3(0.f) ? EnvironmentKind::None
                                                                                    : EnvironmentKind::Constant;
    else
        f.environment = environment.intensity == 0.f ? EnvironmentKind::None : EnvironmentKind::Map;
    f.animatedCamera = mCameraAnimated || cameraPath.kind != CameraPathKind::Static;
}

void Scene::rebuildView(bool instancesToo) {
    mMeshViews.resize(meshes.size());
    for (size_t i = 0; i < meshes.size(); ++i) {
        const Mesh& m = meshes[i];
        MeshView& v = mMeshViews[i];
        v.positions = m.positions.data();
        v.normals = m.normals.data();
        v.tangents = m.tangents.data();
        v.uvs = m.uvs.data();
        v.indices = m.indices.data();
        v.triangleCount = m.triangleCount();
        v.material = m.material;
    }
    mMaterialData.resize(materials.size());
    for (size_t i = 0; i < materials.size(); ++i) {
        const Material& m = materials[i];
        MaterialData& d = mMaterialData[i];
        d.baseColorFactor = m.baseColorFactor;
        d.emissiveFactor = m.emissiveFactor;
        d.metallicFactor = m.metallicFactor;
        d.roughnessFactor = m.roughnessFactor;
        d.normalScale = m.normalScale;
        d.alphaCutoff = m.alphaCutoff;
        d.baseColorTexture = m.baseColorTexture;
        d.metallicRoughnessTexture = m.metallicRoughnessTexture;
        d.normalTexture = m.normalTexture;
        d.emissiveTexture = m.emissiveTexture;
        d.doubleSided = m.doubleSided ? 1u : 0u;
        d.alphaMask = m.alphaMode == AlphaMode::Mask ? 1u : 0u;
        d.alphaBlend = m.alphaMode == AlphaMode::Blend ? 1u : 0u;
        d.ior = m.ior;
        d.specularFactor = m.specularFactor;
        d.specularColorFactor = m.specularColorFactor;
        d.specularF0 = dielectricF0(d);
    }
    mImageViews.resize(images.size());
    for (size_t i = 0; i < images.size(); ++i)
        mImageViews[i] = ImageView8{images[i].texels.data(), images[i].width, images[i].height};
    if (instancesToo || mInstanceViews.size() != instances.size()) {
        mInstanceViews.resize(instances.size());
        for (size_t i = 0; i < instances.size(); ++i) {
            const Instance& inst = instances[i];
            InstanceView& v = mInstanceViews[i];
            v.world = inst.world;
            v.prevWorld = inst.prevWorld;
            // A hidden instance (Instance::visible) is never hit; any finite matrix will do.
            v.normalMatrix = inst.visible() ? glm::transpose(glm::inverse(glm::mat3(inst.world))) : glm::mat3(1.f);
            v.mesh = inst.mesh;
        }
    }
    mView.meshes = mMeshViews.data();
    mView.materials = mMaterialData.data();
    mView.images = mImageViews.data();
    mView.instances = mInstanceViews.data();
    mView.meshCount = uint32_t(mMeshViews.size());
    mView.materialCount = uint32_t(mMaterialData.size());
    mView.imageCount = uint32_t(mImageViews.size());
    mView.instanceCount = uint32_t(mInstanceViews.size());
}

}  // namespace loom

#pragma once
// Scenes: glTF 2.0 content in plain arrays (meshes, materials, images, node
// hierarchy, instances, lights, cameras, animations), updated over time.
// Ray tracing over a scene lives in RayScene.h.
#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <memory>
#include <string>
#include <vector>

#include "loom/Camera.h"
#include "loom/SceneView.h"

namespace loom {

struct Bounds {
    glm::vec3 lo{1e30f}, hi{-1e30f};
    void extend(const glm::vec3& p) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    void extend(const Bounds& b) {
        lo = glm::min(lo, b.lo);
        hi = glm::max(hi, b.hi);
    }
    bool valid() const { return lo.x <= hi.x; }
    glm::vec3 center() const { return 0.5f * (lo + hi); }
    glm::vec3 extent() const { return hi - lo; }
};

/// An 8-bit RGBA image used by materials, stored as in the file. Whether it
/// is sRGB-encoded depends on the material slot that samples it: base colour
/// and emission are sRGB, metallic-roughness and normal maps are linear.
struct SceneImage {
    std::string name;
    uint32_t width = 0, height = 0;
    std::vector<glm::u8vec4> texels;  ///< row 0 = top of the image (glTF uv (0,0))
};

enum class AlphaMode : uint8_t { Opaque, Mask, Blend };

/// glTF metallic-roughness material. Texture references name an image of Scene::images (image -1 = none) with
/// its sampler and KHR_texture_transform.
struct Material {
    std::string name;
    glm::vec4 baseColorFactor{1.f};
    float metallicFactor = 1.f;  ///< glTF default is 1 (fully metallic) when absent
    float roughnessFactor = 1.f;
    glm::vec3 emissiveFactor{0.f};  ///< already multiplied by KHR_materials_emissive_strength
    /// The two factors emissiveFactor is the product of: the file's emissiveFactor and KHR_materials_emissive_strength.
    /// Kept apart for animations (KHR_animation_pointer): Scene::update sets either and recomputes emissiveFactor =
    /// emissiveColor * emissiveStrength for the materials an animation targets (only for those).
    glm::vec3 emissiveColor{0.f};
    float emissiveStrength = 1.f;
    TextureRef baseColorTexture;
    TextureRef metallicRoughnessTexture;  ///< G = roughness, B = metallic
    TextureRef normalTexture;
    float normalScale = 1.f;
    TextureRef emissiveTexture;
    bool doubleSided = false;
    AlphaMode alphaMode = AlphaMode::Opaque;
    float alphaCutoff = 0.5f;
    /// KHR_materials_ior: the dielectric's index of refraction, >= 1; 0 is the extension's special value for a
    /// Fresnel term of 1 (with KHR_materials_specular, the specular-glossiness workflow).
    float ior = 1.5f;
    float specularFactor = 1.f;          ///< KHR_materials_specular: strength of the dielectric specular, [0, 1]
    glm::vec3 specularColorFactor{1.f};  ///< KHR_materials_specular: F0 tint (linear), >= 0, may exceed 1
    bool isEmissive() const { return emissiveFactor.x > 0.f || emissiveFactor.y > 0.f || emissiveFactor.z > 0.f; }
};

/// One glTF primitive: an indexed triangle list with one material. Normals
/// and tangents are always present (generated when the file has none).
struct Mesh {
    std::string name;  ///< "<glTF mesh name>/<primitive index>"
    std::vector<glm::vec3> positions;
    std::vector<glm::vec3> normals;
    std::vector<glm::vec4> tangents;  ///< xyz tangent, w handedness
    std::vector<glm::vec2> uvs;       ///< TEXCOORD_0, or all zero when absent
    std::vector<uint32_t> indices;    ///< 3 per triangle
    uint32_t material = 0;
    Bounds bounds;
    uint32_t triangleCount() const { return uint32_t(indices.size() / 3); }
};

/// A node of the glTF hierarchy.
struct Node {
    std::string name;
    int parent = -1;
    std::vector<int> children;
    glm::vec3 translation{0.f};
    glm::quat rotation{1.f, 0.f, 0.f, 0.f};  ///< (w, x, y, z)
    glm::vec3 scale{1.f};
    bool hasMatrix = false;  ///< a static "matrix" node (not animatable)
    glm::mat4 matrix{1.f};
    glm::mat4 local() const;       ///< T * R * S, or matrix
    std::vector<uint32_t> meshes;  ///< primitives this node draws (indices into Scene::meshes)
    int camera = -1;               ///< index into Scene::cameras
    int light = -1;                ///< index into Scene::lights
};

/// A mesh placed in the world by a node. Its index is the instance id that
/// G-buffers write into vbuffer and meshId.
struct Instance {
    uint32_t node = 0;
    uint32_t mesh = 0;
    glm::mat4 world{1.f};
    glm::mat4 prevWorld{1.f};
    /// Whether the instance is drawn, intersected and lit this frame: its world transform has an inverse whose
    /// entries stay within 1e9, and its translation within kWorldLimit (RayScene.h). A zero scale on any axis (a
    /// common way to hide an object in an animation) hides the instance; it has no object space a ray or a normal
    /// could be carried into.
    bool visible() const;
};

enum class LightType : uint8_t { Point, Spot, Directional };

/// KHR_lights_punctual light; position/direction are in world space after update().
struct Light {
    std::string name;
    LightType type = LightType::Point;
    glm::vec3 color{1.f};
    float intensity = 1.f;  ///< candela (point, spot) or lux (directional), as glTF
    float range = 0.f;      ///< 0 = infinite
    float innerConeAngle = 0.f, outerConeAngle = 0.7853982f;
    int node = -1;
    int source = -1;  ///< the file's KHR_lights_punctual light this one places (animations target it)
    glm::vec3 position{0.f};
    glm::vec3 direction{0.f, 0.f, -1.f};  ///< direction the light points to
};

enum class Interpolation : uint8_t { Linear, Step, CubicSpline };
/// What a channel animates: a node's TRS (glTF's own targets), or, through KHR_animation_pointer, a material's
/// emission (emissiveFactor, KHR_materials_emissive_strength) or a punctual light's intensity or colour.
enum class AnimPath : uint8_t {
    Translation,
    Rotation,
    Scale,
    EmissiveColor,     ///< /materials/{i}/emissiveFactor (VEC3)
    EmissiveStrength,  ///< /materials/{i}/extensions/KHR_materials_emissive_strength/emissiveStrength (SCALAR)
    LightIntensity,    ///< /extensions/KHR_lights_punctual/lights/{i}/intensity (SCALAR)
    LightColor,        ///< /extensions/KHR_lights_punctual/lights/{i}/color (VEC3)
};
/// Whether the path animates emitted light (a material's emission or a punctual light) rather than a node.
inline bool animatesLight(AnimPath path) {
    return path != AnimPath::Translation && path != AnimPath::Rotation && path != AnimPath::Scale;
}

struct AnimationSampler {
    std::vector<float> times;
    /// Values as vec4 (translation/scale and colours use xyz; rotation is quaternion x, y, z, w; scalars use x).
    /// CubicSpline stores (inTangent, value, outTangent) per key, as glTF.
    std::vector<glm::vec4> values;
    Interpolation interpolation = Interpolation::Linear;
    /// Value at time t (clamped to the key range). Rotations are normalised;
    /// linear rotation uses slerp.
    glm::vec4 sample(float t, AnimPath path) const;
};

struct AnimationChannel {
    uint32_t sampler = 0;
    int node = -1;  ///< the node of a TRS path
    AnimPath path = AnimPath::Translation;
    int target = -1;  ///< light paths: the material (Emissive*) or the file's KHR_lights_punctual light (Light*)
};

struct Animation {
    std::string name;
    std::vector<AnimationSampler> samplers;
    std::vector<AnimationChannel> channels;
    float duration() const;
};

/// A triangle with emission (now, or at some time of an animation of its material's emission).
struct EmissiveTriangle {
    uint32_t instance = 0;
    uint32_t primitive = 0;
};

/// Constant colour, or an equirectangular HDR map (radiance).
struct Environment {
    glm::vec3 color{0.f};
    uint32_t width = 0, height = 0;  ///< 0 when constant
    std::vector<glm::vec3> texels;   ///< equirect, row 0 = +Y (up)
    float intensity = 1.f;
    bool isConstant() const { return texels.empty(); }
};

/// A procedural camera motion for scenes whose camera is not animated.
/// Orbit: around the scene's centre, about +Y. Dolly: to and fro along the view direction. Strafe: side to side
/// along the camera's right axis (motion across the view, parallax without a change of depth).
enum class CameraPathKind : uint8_t { Static, Orbit, Dolly, Strafe };
struct CameraPath {
    CameraPathKind kind = CameraPathKind::Static;
    float speed = 1.f;     ///< orbit: radians per second; dolly, strafe: phase of the sine in radians per second
    float amount = 0.25f;  ///< dolly, strafe: amplitude as a fraction of the distance to the target
};

/// What lights the scene from infinitely far away (Scene::environment).
enum class EnvironmentKind : uint8_t {
    None,      ///< black everywhere: a black constant colour, or intensity 0
    Constant,  ///< one colour in every direction: sampled uniformly, no importance-sampling tables
    Map,       ///< an equirectangular map, importance-sampled
};

/// What a scene holds, decided once per scene (Scene::finalize, loadEnvironmentMap; the environment and camera path
/// again at every update, since tools set them after loading), never per pixel. Passes choose kernels that leave out
/// the work a feature needs when the scene lacks it. Each flag is conservative: true whenever the work might matter.
struct SceneFeatures {
    bool textures = false;     ///< a material samples an image (base colour, metallic-roughness, normal, emission)
    bool normalMaps = false;   ///< a material has a normal texture
    bool alphaTested = false;  ///< a material's alphaMode is MASK or BLEND (honoured with alpha testing on)
    bool emissiveTriangles = false;  ///< Scene::emissiveTriangles is not empty (animated emission counts at any time)
    bool punctualLights = false;     ///< a KHR_lights_punctual light is placed in the scene
    EnvironmentKind environment = EnvironmentKind::None;
    /// No material has a specular lobe: metallicFactor 0 (so metallic is 0 whatever its texture says) and
    /// specularFactor 0 (KHR_materials_specular: the dielectric's f0 and f90 are both 0). The glTF BRDF is then
    /// exactly its diffuse lobe, baseColor / pi, and every GGX term is a product with 0.
    bool diffuseOnly = false;
    bool animatedNodes = false;  ///< an animation moves a node (instances, lights or cameras may move)
    bool animatedLights =
        false;  ///< an animation changes a material's emission or a punctual light's colour or intensity
    bool animatedCamera = false;  ///< the render camera moves: an animated glTF camera, or a procedural camera path
    /// Whether anything may change between frames. A static scene builds its ray-tracing acceleration structure and
    /// its light list once, and its motion vectors are the camera's alone.
    bool animated() const { return animatedNodes || animatedLights || animatedCamera; }
};

/// Texture limits of Scene::load. Images are decoded to 8-bit RGBA (4 bytes a texel); the sizes are checked from the
/// image header before anything is decoded or allocated. 16384 is the largest 2D texture llvmpipe (and most GPUs)
/// accept, so GBufferRaster can upload any texture the loader keeps.
inline constexpr uint32_t kMaxTextureSide = 16384;
/// The most texels one texture may have: 2^28, a 16384 x 16384 image, 1 GiB decoded.
inline constexpr uint64_t kMaxTextureTexels = uint64_t(1) << 28;
/// The default budget for the decoded textures of one scene: 4 GiB.
inline constexpr uint64_t kDefaultTextureBudget = uint64_t(4) << 30;

struct SceneLoadOptions {
    /// Warnings (degenerate triangles dropped, ...) go to the log and are collected in Scene::warnings.
    bool generateTangents = true;
    /// Largest width or height of a texture, and most texels of one: beyond either, loading fails (bad input).
    uint32_t maxTextureSide = kMaxTextureSide;
    uint64_t maxTextureTexels = kMaxTextureTexels;
    /// Bytes all decoded textures of the scene may take together (images shared by several textures, or the same
    /// file named by several images, count once); beyond it loading fails (bad input).
    uint64_t textureBudgetBytes = kDefaultTextureBudget;
    /// A texture whose image file is missing, empty or cannot be decoded is an error (bad input); with this set it is
    /// dropped with a warning instead, and the material renders with its factors alone.
    bool allowMissingTextures = false;
};

class RayScene;

class Scene {
public:
    Scene();
    ~Scene();
    Scene(const Scene&) = delete;
    Scene& operator=(const Scene&) = delete;

    /// Loads a .gltf or .glb. Throws loom::Error (BadInput) naming the file
    /// and the offending mesh/accessor/material/image for: missing file, truncated
    /// buffer, accessor out of range, negative index or offset, NaN/Inf vertex
    /// data, unsupported required extension, node cycle, empty scene, a texture
    /// image that is missing or cannot be decoded (unless
    /// options.allowMissingTextures), a texture beyond the limits of `options`,
    /// and running out of memory. Recoverable problems (degenerate triangles,
    /// out-of-range factors) are warnings, and loading goes on.
    static std::shared_ptr<Scene> load(const std::filesystem::path& file, const SceneLoadOptions& options = {});

    /// Evaluates animations and the camera path at `time` (seconds): every
    /// node's world transform, instances' world and prevWorld (prev = the
    /// last update's value; on the first update prev = current), lights, the
    /// camera (prevWorld likewise), and the ray-tracing instances.
    void update(double time);
    /// Makes prev equal current everywhere (camera cut / first frame).
    void cutMotion();

    // Content (public so tests and tools can build scenes in code; call
    // finalize() after editing).
    std::string name;
    std::filesystem::path file;
    std::vector<Mesh> meshes;
    std::vector<Material> materials;
    std::vector<SceneImage> images;
    std::vector<Node> nodes;
    std::vector<int> roots;  ///< root nodes of the active glTF scene
    std::vector<Instance> instances;
    std::vector<Light> lights;
    std::vector<Camera> cameras;  ///< glTF cameras (world filled by update); may be empty
    std::vector<Animation> animations;
    std::vector<EmissiveTriangle> emissiveTriangles;
    Environment environment;
    std::vector<std::string> warnings;

    /// The camera passes render from: a copy of the glTF camera chosen by
    /// activeCamera (or a default framing the bounds), driven by cameraPath
    /// when the camera is not animated.
    Camera camera;
    int activeCamera = -1;
    CameraPath cameraPath;

    /// Builds instances from the node hierarchy, fills bounds, emissive
    /// triangles, a default camera when there is none, and the ray scene.
    void finalize();

    /// Places the render camera (the pose a camera path starts from; an
    /// animated glTF camera ignores it). Takes effect now and at every update.
    void setCameraPose(const glm::mat4& world);

    Bounds bounds() const;          ///< world bounds at the last update
    float animationLength() const;  ///< longest animation, seconds
    size_t triangleCount() const;   ///< over instances
    bool hasMotion() const;         ///< animations (of nodes or of light) or a camera path
    /// Whether the last update() changed emitted light: a material's emission or a punctual light's colour or
    /// intensity, driven by an animation. Like a moved instance, it ends an accumulation; false after cutMotion().
    bool lightingChanged() const { return mLightingChanged; }
    /// Times (seconds, ascending, each once) at which an animation of emitted light jumps: a STEP key whose value
    /// differs from the key before it, or a LINEAR or CUBICSPLINE key at the same time as the key before it with
    /// another value. The value after the jump holds from that time on. Empty when the light only changes smoothly.
    std::vector<float> lightStepTimes() const;
    /// Whether anything lights the scene at the last update (animated emission included): an instance of an emissive
    /// material (with a texel that is not black when the emission is textured), a punctual light of nonzero intensity,
    /// or an environment that is not black.
    bool emitsLight() const;
    bool cameraAnimated() const { return mCameraAnimated; }  ///< the glTF camera is animated (setCameraPose ignored)
    /// What the scene holds (SceneFeatures): computed by finalize() and loadEnvironmentMap(), its environment and
    /// camera flags again by update().
    const SceneFeatures& features() const { return mFeatures; }
    /// Counts finalize() calls and the updates that moved an instance: what a pass built from the instances' world
    /// transforms (a light list) is still valid while it stays the same and no emission is animated.
    uint64_t geometryVersion() const { return mGeometryVersion; }
    /// Counts finalize() calls only: what a pass built from the meshes alone (a per-mesh BVH) is still valid while it
    /// stays the same, however the instances move.
    uint64_t meshVersion() const { return mMeshVersion; }

    const RayScene& rayScene() const { return *mRayScene; }
    /// Plain view for kernels; rebuilt by finalize() and update().
    const SceneView& view() const { return mView; }
    /// Loads an equirectangular .hdr (Radiance) as the environment.
    void loadEnvironmentMap(const std::filesystem::path& file);

private:
    void linkHierarchy();
    void chooseCamera();
    void updateWorldTransforms();
    void rebuildView(bool instancesToo = true);
    std::vector<float> lightState() const;
    void computeFeatures();
    void updateDynamicFeatures();
    SceneView mView;
    std::vector<MeshView> mMeshViews;
    std::vector<MaterialData> mMaterialData;
    std::vector<ImageView8> mImageViews;
    std::vector<InstanceView> mInstanceViews;
    std::unique_ptr<RayScene> mRayScene;
    std::vector<glm::mat4> mNodeWorld;
    bool mUpdated = false;
    glm::mat4 mCameraBase{1.f};  // camera pose before the procedural path
    Bounds mRestBounds;          // world bounds at time 0: the pivot of camera paths
    bool mCameraAnimated = false;
    bool mLightingChanged = false;
    SceneFeatures mFeatures;
    uint64_t mGeometryVersion = 0;
    uint64_t mMeshVersion = 0;
    std::vector<float> mLightState;  // emission and punctual light values the last update left, when animated
};

}  // namespace loom

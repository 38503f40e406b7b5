#pragma once
// A plain view of a Scene for per-pixel kernels: pointers and counts only, so
// kernels compile for CUDA too. Built by Scene (Scene::view()), valid until
// the scene is edited or destroyed.
#include <cstdint>

#include <glm/glm.hpp>

#include "loom/Kernel.h"

namespace loom {

struct MeshView {
    const glm::vec3* positions = nullptr;
    const glm::vec3* normals = nullptr;
    const glm::vec4* tangents = nullptr;
    const glm::vec2* uvs = nullptr;
    const uint32_t* indices = nullptr;
    uint32_t triangleCount = 0;
    uint32_t material = 0;
};

struct ImageView8 {
    const glm::u8vec4* texels = nullptr;
    uint32_t width = 0, height = 0;
};

/// How texel coordinates outside an image are mapped into it, for each axis
/// (glTF sampler wrapS/wrapT; the GL modes of the same names).
enum class TextureWrap : uint32_t { Repeat, ClampToEdge, MirroredRepeat };

/// One texture reference of a material: the image, its sampler and its
/// KHR_texture_transform, as SurfaceKernels.h sampleTexture uses them.
struct TextureRef {
    int32_t image = -1;                       ///< index into the scene's images; -1 = no texture
    TextureWrap wrapS = TextureWrap::Repeat;  ///< along u (image columns)
    TextureWrap wrapT = TextureWrap::Repeat;  ///< along v (image rows)
    /// 1: the nearest texel; 0: bilinear. Loom samples points (a ray, a pixel centre) from one level with no
    /// footprint, so this is the sampler's magFilter, or minFilter's base filter when magFilter is not given.
    uint32_t nearest = 0;
    /// KHR_texture_transform as a 2x3 affine map (three columns): uv' = transform * (u, v, 1). Identity when the
    /// reference has no transform.
    glm::mat3x2 transform{1.f};
};

/// Material parameters as kernels need them (see Material in Scene.h).
struct MaterialData {
    glm::vec4 baseColorFactor{1.f};
    glm::vec3 emissiveFactor{0.f};
    float metallicFactor = 1.f;
    float roughnessFactor = 1.f;
    float normalScale = 1.f;
    float alphaCutoff = 0.5f;
    TextureRef baseColorTexture;
    TextureRef metallicRoughnessTexture;
    TextureRef normalTexture;
    TextureRef emissiveTexture;
    uint32_t doubleSided = 0;
    uint32_t alphaMask = 0;              ///< 1 for AlphaMode::Mask
    uint32_t alphaBlend = 0;             ///< 1 for AlphaMode::Blend (stochastic transparency, see surfaceCovers)
    float ior = 1.5f;                    ///< KHR_materials_ior: >= 1, or 0 (Fresnel term 1)
    float specularFactor = 1.f;          ///< KHR_materials_specular, in [0, 1]
    glm::vec3 specularColorFactor{1.f};  ///< KHR_materials_specular, >= 0 (may exceed 1)
    glm::vec3 specularF0{0.04f};         ///< dielectricF0() of the three above, computed once per material
};

/// The dielectric's reflectance at normal incidence: ((ior - 1) / (ior + 1))^2 (KHR_materials_ior; ior = 0, the
/// extension's special value, gives 1), tinted by specularColorFactor and clamped to 1, then scaled by
/// specularFactor (KHR_materials_specular). In double, so glTF's default (ior 1.5, no specular extension) is 0.04f
/// exactly. Scene fills MaterialData::specularF0 with it; kernels read the field.
inline glm::vec3 dielectricF0(const MaterialData& mat) {
    const double r = (double(mat.ior) - 1.0) / (double(mat.ior) + 1.0);
    const glm::dvec3 f0 = glm::min(r * r * glm::dvec3(mat.specularColorFactor), glm::dvec3(1.0));
    return glm::vec3(f0 * double(mat.specularFactor));
}

struct InstanceView {
    glm::mat4 world{1.f};
    glm::mat4 prevWorld{1.f};
    glm::mat3 normalMatrix{1.f};  ///< inverse transpose of world's upper 3x3
    uint32_t mesh = 0;
};

struct SceneView {
    const MeshView* meshes = nullptr;
    const MaterialData* materials = nullptr;
    const ImageView8* images = nullptr;
    const InstanceView* instances = nullptr;
    uint32_t meshCount = 0, materialCount = 0, imageCount = 0, instanceCount = 0;
};

}  // namespace loom

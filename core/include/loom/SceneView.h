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

/// Material parameters as kernels need them (see Material in Scene.h).
struct MaterialData {
    glm::vec4 baseColorFactor{1.f};
    glm::vec3 emissiveFactor{0.f};
    float metallicFactor = 1.f;
    float roughnessFactor = 1.f;
    float normalScale = 1.f;
    float alphaCutoff = 0.5f;
    int32_t baseColorTexture = -1;
    int32_t metallicRoughnessTexture = -1;
    int32_t normalTexture = -1;
    int32_t emissiveTexture = -1;
    uint32_t doubleSided = 0;
    uint32_t alphaMask = 0;   ///< 1 for AlphaMode::Mask
    uint32_t alphaBlend = 0;  ///< 1 for AlphaMode::Blend (stochastic transparency, see surfaceCovers)
};

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

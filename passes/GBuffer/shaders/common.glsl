#version 450 core

// Per-frame camera data (std140; FrameGpu on the C++ side).
layout(std140, binding = 0) uniform FrameBlock {
    mat4 viewProj;      // unjittered
    mat4 prevViewProj;  // unjittered, last frame's camera
    mat4 view;
    mat4 prevView;
    mat4 proj;
    vec4 camOrigin;
    vec4 camRight;
    vec4 camUp;
    vec4 camForward;
    vec4 lens;          // x: tan(fovY / 2), y: aspect, z: nearZ
    vec4 viewport;      // x: width, y: height (pixels)
    vec4 jitter;        // xy: NDC offset (Camera::jitterNdcOffset), zw: jitter in pixels
    uvec4 counters;     // x: frame index (low 32 bits), for stochastic transparency
} uFrame;

// Per draw: x = instance id, y = material index; the instance's transforms.
// Plain uniforms rather than a storage buffer: helper invocations need them
// too (see the derivatives in the fragment shader).
layout(location = 0) uniform uvec4 uDraw;
layout(location = 1) uniform mat4 uWorld;
layout(location = 2) uniform mat4 uPrevWorld;
layout(location = 3) uniform mat3 uNormalMatrix;  // inverse transpose of uWorld's upper 3x3

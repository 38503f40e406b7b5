layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aNormal;
out vec3 vObjPos;
out vec3 vPosW;
out vec3 vNormalW;

// Several geometry passes (more channels than draw buffers) depth-test
// against the first pass with GL_EQUAL, which needs bit-identical depth
// across programs (GLSL 4.50, section 4.8.1).
invariant gl_Position;

void main() {
    const vec4 posW = uWorld * vec4(aPosition, 1.0);
    vec4 clip = uFrame.viewProj * posW;
    // Sub-pixel jitter: an NDC offset, hence scaled by w in clip space.
    clip.xy += uFrame.jitter.xy * clip.w;
    // Reversed, infinite depth: z_ndc = nearZ / viewDepth with the
    // GL_ZERO_TO_ONE clip control. Float depth keeps a constant relative
    // precision at every distance this way, and there is no far plane (the
    // RT pass has none either). clip.w is the view depth for Camera::proj.
    gl_Position = vec4(clip.xy, uFrame.lens.z, clip.w);
    vObjPos = aPosition;
    vPosW = posW.xyz;
    vNormalW = uNormalMatrix * aNormal;
}

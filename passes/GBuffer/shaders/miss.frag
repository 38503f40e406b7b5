
bool clipToUv(vec4 clip, out vec2 uv) {
    uv = vec2(0.5 * clip.x / clip.w + 0.5, 0.5 - 0.5 * clip.y / clip.w);
    return clip.w > 1e-12;
}

// GBufferKernels.h missSample: zeros, linearZ (-1, 0), ids ~0u, and the
// motion of CameraKernels.h missMotion: the pixel's direction at infinity
// seen through the previous camera's rotation (translation does not move
// the sky).
void main() {
#ifdef OUT_POSW
    oPosW = vec4(0.0);
#endif
#ifdef OUT_NORMW
    oNormW = vec4(0.0);
#endif
#ifdef OUT_FACENORMALW
    oFaceNormalW = vec4(0.0);
#endif
#ifdef OUT_LINEARZ
    oLinearZ = vec2(-1.0, 0.0);
#endif
#ifdef OUT_PNFWIDTH
    oPnFwidth = vec2(0.0);
#endif
#ifdef OUT_MVEC
    const vec2 pix = gl_FragCoord.xy + uFrame.jitter.zw;
    const float nx = 2.0 * pix.x / uFrame.viewport.x - 1.0;
    const float ny = 1.0 - 2.0 * pix.y / uFrame.viewport.y;
    const vec3 dir = uFrame.camForward.xyz + uFrame.camRight.xyz * (nx * uFrame.lens.x * uFrame.lens.y) +
                     uFrame.camUp.xyz * (ny * uFrame.lens.x);
    vec2 uvCur, uvPrev;
    const bool curOk = clipToUv(uFrame.proj * (uFrame.view * vec4(dir, 0.0)), uvCur);
    const bool prevOk = clipToUv(uFrame.proj * (uFrame.prevView * vec4(dir, 0.0)), uvPrev);
    oMvec = curOk && prevOk ? uvPrev - uvCur : vec2(0.0);
#endif
#ifdef OUT_ALBEDO
    oAlbedo = vec4(0.0);
#endif
#ifdef OUT_SPECALBEDO
    oSpecAlbedo = vec4(0.0);
#endif
#ifdef OUT_EMISSION
    oEmission = vec4(0.0);
#endif
#ifdef OUT_VBUFFER
    oVBuffer = uvec4(0xFFFFFFFFu);
#endif
#ifdef OUT_MESHID
    oMeshId = 0xFFFFFFFFu;
#endif
}

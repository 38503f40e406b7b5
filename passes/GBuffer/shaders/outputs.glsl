#ifdef OUT_POSW
layout(location = OUT_POSW) out vec4 oPosW;
#endif
#ifdef OUT_NORMW
layout(location = OUT_NORMW) out vec4 oNormW;
#endif
#ifdef OUT_FACENORMALW
layout(location = OUT_FACENORMALW) out vec4 oFaceNormalW;
#endif
#ifdef OUT_LINEARZ
layout(location = OUT_LINEARZ) out vec2 oLinearZ;
#endif
#ifdef OUT_PNFWIDTH
layout(location = OUT_PNFWIDTH) out vec2 oPnFwidth;
#endif
#ifdef OUT_MVEC
layout(location = OUT_MVEC) out vec2 oMvec;
#endif
#ifdef OUT_ALBEDO
layout(location = OUT_ALBEDO) out vec4 oAlbedo;
#endif
#ifdef OUT_SPECALBEDO
layout(location = OUT_SPECALBEDO) out vec4 oSpecAlbedo;
#endif
#ifdef OUT_EMISSION
layout(location = OUT_EMISSION) out vec4 oEmission;
#endif
#ifdef OUT_VBUFFER
layout(location = OUT_VBUFFER) out uvec4 oVBuffer;
#endif
#ifdef OUT_MESHID
layout(location = OUT_MESHID) out uint oMeshId;
#endif

// The path tracer's BRDF (passes/PathTracer/BRDF.h), tested by mathematical properties as pbrt-v4's bsdfs_test
// does: the pdf is a density, sampling matches evaluation, no energy is created, reciprocity, the smooth and rough
// limits, the GGX normalisations, and a chi-square test of sampled directions against the pdf.
//
// Integrals are computed by quadrature in double precision on grids graded toward the normal, so that lobes as narrow
// as alpha = 1e-3 are resolved; Monte Carlo estimates use a fixed-seed PCG32, so every run is identical.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "../BRDF.h"

using namespace loom;
using namespace loom::pt;

namespace {

constexpr double kPiD = std::numbers::pi;

/// PCG32, XSH-RR variant (O'Neill 2014, "PCG: A Family of Simple Fast Space-Efficient Statistically Good Algorithms
/// for Random Number Generation"): small, deterministic and statistically sound for these tests.
class Pcg32 {
public:
    explicit Pcg32(uint64_t seed, uint64_t stream = 1) : inc_((stream << 1u) | 1u) {
        next();
        state_ += seed;
        next();
    }
    uint32_t next() {
        const uint64_t old = state_;
        state_ = old * 6364136223846793005ull + inc_;
        const uint32_t xorShifted = uint32_t(((old >> 18u) ^ old) >> 27u);
        const uint32_t rot = uint32_t(old >> 59u);
        return (xorShifted >> rot) | (xorShifted << ((32u - rot) & 31u));
    }
    /// Uniform in [0, 1): 24 random bits, exactly representable.
    float uniform() { return float(next() >> 8) * 0x1p-24f; }
    glm::vec2 uniform2() {
        const float a = uniform();
        return glm::vec2(a, uniform());
    }

private:
    uint64_t state_ = 0;
    uint64_t inc_;
};

/// A tilted shading normal, so the tests go through makeFrame() and the world-space API rather than the identity.
const glm::vec3 kNormal = glm::normalize(glm::vec3(0.3f, -0.5f, 0.8f));

/// Unit direction at polar angle thetaDeg (degrees, from the frame's normal) and azimuth phi (radians).
glm::vec3 direction(const Frame& frame, float thetaDeg, float phi) {
    const float theta = thetaDeg * float(kPiD / 180.0);
    return glm::normalize(
        frame.toWorld(glm::vec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta))));
}

/// Integral of g(w) over the hemisphere around +z, w in local coordinates. Midpoint rule in (s, phi) with polar angle
/// theta = (pi/2) s^3: samples crowd toward the pole, where GGX lobes with alpha down to 1e-3 concentrate, while the
/// spacing near the horizon stays about half a degree (nS = 512).
template <class G>
auto integrateOverHemisphere(G&& g, int nS = 512, int nPhi = 256) {
    using Value = decltype(g(glm::vec3(0.f)));  // double or glm::dvec3
    Value sum(0.0);
    const double dPhi = 2.0 * kPiD / nPhi;
    for (int i = 0; i < nS; ++i) {
        const double s = (i + 0.5) / nS;
        const double theta = 0.5 * kPiD * s * s * s;
        const double dTheta = 1.5 * kPiD * s * s / nS;
        const double sinT = std::sin(theta), cosT = std::cos(theta);
        Value ring(0.0);
        for (int j = 0; j < nPhi; ++j) {
            const double phi = (j + 0.5) * dPhi;
            ring += g(glm::vec3(float(sinT * std::cos(phi)), float(sinT * std::sin(phi)), float(cosT)));
        }
        sum += ring * sinT * dTheta * dPhi;
    }
    return sum;
}

/// Integral of g(wi) over the whole sphere of directions wi, for the view wo (world space), computed over microfacet
/// normals: wi = reflect(-wo, h) maps the hemisphere {h : wo.h > 0} onto the sphere with dwi = 4 (wo.h) dh
/// (Walter et al. 2007, eq. 14), and in h the specular lobe is a narrow cap around n at any view angle, which the
/// graded grid resolves. Half vectors below the surface are skipped: they reflect below the surface (wi.n < 0), where
/// f and the diffuse pdf vanish, and have D(h) = 0, so no integrand of these tests is lost.
template <class G>
auto integrateOverDirections(const Frame& frame, glm::vec3 wo, G&& g, int nS = 512, int nPhi = 256) {
    using Value = decltype(g(glm::vec3(0.f)));  // double or glm::dvec3
    return integrateOverHemisphere(
        [&](glm::vec3 hLocal) {
            const glm::vec3 h = frame.toWorld(hLocal);
            const float c = glm::dot(wo, h);
            if (c <= 0.f) return Value(0.0);
            const glm::vec3 wi = glm::normalize(2.f * c * h - wo);
            return g(wi) * (4.0 * double(c));
        },
        nS, nPhi);
}

/// Directional albedo, channel by channel: integral of f(wo, wi) (n.wi)+ over wi.
glm::dvec3 albedoByQuadrature(const BrdfInputs& in, const Frame& frame, glm::vec3 wo, int nS = 512, int nPhi = 256) {
    return integrateOverDirections(
        frame, wo,
        [&](glm::vec3 wi) { return glm::dvec3(evalBrdf(in, frame.n, wo, wi) * std::fmax(0.f, glm::dot(frame.n, wi))); },
        nS, nPhi);
}

struct Case {
    float roughness, metallic, viewDeg;
};

std::string describe(const Case& c) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "roughness %.2f metallic %.1f view %.0f deg", c.roughness, c.metallic, c.viewDeg);
    return buf;
}

/// The standard grid: smooth to rough, dielectric and metal, views from normal to grazing.
std::vector<Case> standardCases() {
    std::vector<Case> cases;
    for (float r : {0.05f, 0.2f, 0.5f, 1.f})
        for (float m : {0.f, 1.f})
            for (float v : {0.f, 30.f, 60.f, 85.f}) cases.push_back({r, m, v});
    return cases;
}

/// Mean and standard error of a stream of values.
struct MeanEstimate {
    double sum = 0.0, sumSq = 0.0;
    int n = 0;
    void add(double x) {
        sum += x;
        sumSq += x * x;
        ++n;
    }
    double mean() const { return sum / n; }
    double standardError() const {
        const double m = mean();
        return std::sqrt(std::max(0.0, sumSq / n - m * m) / (n - 1));
    }
};

}  // namespace

// ---------------------------------------------------------------------------------------------------------------------
// Building blocks

TEST(Brdf, PolynomialCosSinMatchLibm) {
    // Sampling's own cos/sin: within float rounding of the double-precision values over the whole turn, on |cos| and
    // |sin| both (so a quadrant mix-up cannot pass), and exactly 1 and 0 at u = 0.
    double worst = 0.0;
    const int n = 1 << 20;
    for (int i = 0; i < n; ++i) {
        const float u = float(i) / float(n);
        const glm::vec2 cs = cosSinTurn(u);
        const double phi = 2.0 * kPiD * double(u);
        worst = std::max({worst, std::fabs(double(cs.x) - std::cos(phi)), std::fabs(double(cs.y) - std::sin(phi))});
    }
    EXPECT_LT(worst, 1e-6);
    EXPECT_EQ(cosSinTurn(0.f), glm::vec2(1.f, 0.f));
    double worstQuarter = 0.0;
    for (int i = -1000; i <= 1000; ++i) {
        const float x = float(i) / 1000.f * 0.25f * float(kPiD);
        const glm::vec2 cs = cosSinQuarter(x);
        worstQuarter = std::max({worstQuarter, std::fabs(double(cs.x) - std::cos(double(x))),
                                 std::fabs(double(cs.y) - std::sin(double(x)))});
    }
    EXPECT_LT(worstQuarter, 2e-7);
}

TEST(Brdf, FrameIsOrthonormalAndRightHanded) {
    Pcg32 rng(7);
    std::vector<glm::vec3> normals = {{0.f, 0.f, 1.f},
                                      {0.f, 0.f, -1.f},
                                      {1.f, 0.f, 0.f},
                                      {0.f, 1.f, 0.f},
                                      glm::normalize(glm::vec3(1e-4f, 0.f, -1.f)),
                                      kNormal};
    for (int i = 0; i < 1000; ++i) {
        const glm::vec2 u = rng.uniform2();
        const float z = 1.f - 2.f * u.x, r = std::sqrt(std::fmax(0.f, 1.f - z * z));
        normals.push_back(glm::vec3(r * std::cos(2.f * kPi * u.y), r * std::sin(2.f * kPi * u.y), z));
    }
    for (const glm::vec3& n : normals) {
        const Frame f = makeFrame(n);
        EXPECT_NEAR(glm::length(f.t), 1.f, 1e-5f) << n.x << " " << n.y << " " << n.z;
        EXPECT_NEAR(glm::length(f.b), 1.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.t, f.b), 0.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.t, n), 0.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.b, n), 0.f, 1e-5f);
        EXPECT_LT(glm::length(glm::cross(f.t, f.b) - n), 1e-5f);
        const glm::vec3 v(0.3f, -0.2f, 0.9f);
        EXPECT_LT(glm::length(f.toWorld(f.toLocal(v)) - v), 1e-5f);
    }
}

TEST(Brdf, InputsFromSurfaceHit) {
    SurfaceHit hit;
    hit.baseColor = glm::vec3(0.2f, 0.4f, 0.6f);
    hit.metallic = 0.3f;
    hit.roughness = 0.7f;
    const BrdfInputs in = brdfInputs(hit);
    EXPECT_EQ(in.baseColor, hit.baseColor);
    EXPECT_EQ(in.metallic, hit.metallic);
    EXPECT_EQ(in.roughness, hit.roughness);
    EXPECT_LT(glm::length(brdfF0(in) - specularF0(hit)), 1e-7f);
}

TEST(Brdf, BelowSurfaceIsZero) {
    const Frame frame = makeFrame(kNormal);
    const BrdfInputs in{glm::vec3(0.8f), 0.5f, 0.3f};
    const glm::vec3 above = direction(frame, 30.f, 1.f), below = direction(frame, 120.f, 2.f);
    EXPECT_EQ(evalBrdf(in, kNormal, above, below), glm::vec3(0.f));
    EXPECT_EQ(evalBrdf(in, kNormal, below, above), glm::vec3(0.f));
    EXPECT_EQ(pdfBrdf(in, kNormal, below, above), 0.f);
    Pcg32 rng(3);
    for (int i = 0; i < 100; ++i) EXPECT_FALSE(sampleBrdf(in, kNormal, below, rng.uniform2(), rng.uniform()).valid);
}

// ---------------------------------------------------------------------------------------------------------------------
// 1. The pdf is a density: it integrates to 1 over the sphere (sampleBrdf's invalid below-surface samples included).

TEST(Brdf, PdfIntegratesToOne) {
    double worst = 0.0;
    for (const Case& c : standardCases()) {
        const BrdfInputs in{glm::vec3(0.9f, 0.5f, 0.15f), c.metallic, c.roughness};
        const Frame frame = makeFrame(kNormal);
        const glm::vec3 wo = direction(frame, c.viewDeg, 0.4f);
        const double integral =
            integrateOverDirections(frame, wo, [&](glm::vec3 wi) { return double(pdfBrdf(in, kNormal, wo, wi)); });
        // The quadrature's error is ~1e-5 here (it resolves lobes down to alpha = 1e-3); 1e-3 leaves a margin.
        EXPECT_NEAR(integral, 1.0, 1e-3) << describe(c);
        worst = std::max(worst, std::fabs(integral - 1.0));
    }
    std::printf("[ pdf ] largest |integral - 1| over %zu cases: %.2e\n", standardCases().size(), worst);
}

// ---------------------------------------------------------------------------------------------------------------------
// 2. Sampling matches evaluation.

TEST(Brdf, SampleWeightAndPdfMatchEvaluation) {
    // Every sample's pdf must be pdfBrdf() and its weight f cos / pdf, or MIS and the estimator disagree. sampleBrdf()
    // evaluates both for the returned world-space wi, so they agree to rounding.
    Pcg32 rng(11);
    int checked = 0;
    for (const Case& c : standardCases()) {
        const BrdfInputs in{glm::vec3(0.9f, 0.5f, 0.15f), c.metallic, c.roughness};
        const Frame frame = makeFrame(kNormal);
        const glm::vec3 wo = direction(frame, c.viewDeg, 0.4f);
        for (int i = 0; i < 2000; ++i) {
            const BrdfSample s = sampleBrdf(in, kNormal, wo, rng.uniform2(), rng.uniform());
            if (!s.valid) continue;
            ++checked;
            ASSERT_NEAR(glm::length(s.wi), 1.f, 1e-5f) << describe(c);
            ASSERT_GT(glm::dot(s.wi, kNormal), 0.f) << describe(c);
            const float pdf = pdfBrdf(in, kNormal, wo, s.wi);
            ASSERT_NEAR(s.pdf, pdf, 1e-6f * pdf) << describe(c);
            const glm::vec3 expected = evalBrdf(in, kNormal, wo, s.wi) * (glm::dot(kNormal, s.wi) / pdf);
            for (int k = 0; k < 3; ++k) {
                ASSERT_TRUE(std::isfinite(s.weight[k])) << describe(c);
                ASSERT_NEAR(s.weight[k], expected[k], 1e-4f * std::fmax(expected[k], 1e-3f)) << describe(c);
            }
            // The local-frame sampler agrees with the world-space one up to the frame change's rounding (relative
            // ~1e-3 at most, for the narrow grazing lobe of roughness 0.05).
            const glm::vec3 woLocal = frame.toLocal(wo), wiLocal = frame.toLocal(s.wi);
            ASSERT_NEAR(pdfBrdfLocal(in, woLocal, wiLocal), pdf, 1e-6f * pdf);
            const BrdfEval e = evalBrdfAndPdf(in, kNormal, wo, s.wi);
            ASSERT_EQ(e.pdf, pdf);
            ASSERT_EQ(e.f, evalBrdf(in, kNormal, wo, s.wi));
        }
    }
    EXPECT_GT(checked, 50000);
}

TEST(Brdf, SampledAlbedoMatchesQuadrature) {
    // E[weight] over sampleBrdf() (invalid samples count as 0) is the directional albedo: integral of f cos.
    constexpr int kSamples = 1 << 16;
    double worstDifference = 0.0, worstSigmas = 0.0;
    for (const Case& c : standardCases()) {
        const BrdfInputs in{glm::vec3(0.9f, 0.5f, 0.15f), c.metallic, c.roughness};
        const Frame frame = makeFrame(kNormal);
        const glm::vec3 wo = direction(frame, c.viewDeg, 0.4f);
        const glm::dvec3 reference = albedoByQuadrature(in, frame, wo);
        Pcg32 rng(1234, uint64_t(c.viewDeg * 100 + c.roughness * 10 + c.metallic));
        MeanEstimate est[3];
        for (int i = 0; i < kSamples; ++i) {
            const BrdfSample s = sampleBrdf(in, kNormal, wo, rng.uniform2(), rng.uniform());
            for (int k = 0; k < 3; ++k) est[k].add(s.valid ? s.weight[k] : 0.0);
        }
        for (int k = 0; k < 3; ++k) {
            // 4.5 standard errors, plus the quadrature's own error.
            const double sigma = est[k].standardError();
            EXPECT_NEAR(est[k].mean(), reference[k], 4.5 * sigma + 1e-3)
                << describe(c) << " channel " << k << " standard error " << sigma;
            const double difference = std::fabs(est[k].mean() - reference[k]);
            worstDifference = std::max(worstDifference, difference);
            if (sigma > 1e-4) worstSigmas = std::max(worstSigmas, difference / sigma);
        }
    }
    std::printf("[ albedo ] largest |MC - quadrature| %.2e; in standard errors (where > 1e-4) %.2f\n", worstDifference,
                worstSigmas);
}

TEST(Brdf, SampleWeightsAreBounded) {
    // With VNDF sampling the GGX lobe's weight is F G2 / G1 <= 1 per unit lobe probability. The other lobes are drawn
    // from the cosine-weighted hemisphere, so their weight is pi f_other / (1 - pSpec), bounded by the largest value
    // of f_other over the hemisphere (otherLobes() depends on n.wi only). The mixture's weight is at most the sum:
    // no fireflies from the BRDF, including the mirror limit. Kulla and Conty's lobe of a nearly smooth metal seen at
    // grazing angles is the largest of these (it returns what single scattering loses there, and loses little
    // elsewhere): up to ~30 at roughness 0.1 and 89 degrees.
    Pcg32 rng(5);
    float largest = 0.f;
    for (bool multiScatter : {true, false}) {
        for (float r : {0.f, 0.01f, 0.1f, 0.4f, 1.f}) {
            for (float m : {0.f, 0.5f, 1.f}) {
                BrdfInputs in{glm::vec3(1.f), m, r};
                in.multiScatter = multiScatter;
                const Frame frame = makeFrame(kNormal);
                for (float view : {0.f, 45.f, 80.f, 89.f}) {
                    const glm::vec3 wo = direction(frame, view, 2.f);
                    const float muO = glm::dot(kNormal, wo);
                    const BrdfLobes lobes = makeBrdfLobes(in, muO);
                    const float p = lobes.pSpec;
                    float otherMax = 0.f;  // the plain model's diffuse weight is largest at wo.h = 1 (w = 0)
                    for (int i = 0; i <= 4096; ++i) {
                        const glm::vec3 o = otherLobes(lobes, float(i) / 4096.f, 0.f);
                        otherMax = std::fmax(otherMax, std::fmax(o.r, std::fmax(o.g, o.b)));
                    }
                    const float bound = 1.f / p + (p < 1.f ? kPi * otherMax / (1.f - p) : 0.f);
                    for (int i = 0; i < 4000; ++i) {
                        const BrdfSample s = sampleBrdf(in, kNormal, wo, rng.uniform2(), rng.uniform());
                        if (!s.valid) continue;
                        const float w = std::fmax(s.weight.r, std::fmax(s.weight.g, s.weight.b));
                        ASSERT_TRUE(std::isfinite(w));
                        ASSERT_LE(w, bound * 1.01f) << "roughness " << r << " metallic " << m << " view " << view
                                                    << (multiScatter ? "" : " plain");
                        largest = std::fmax(largest, w);
                    }
                }
            }
        }
    }
    std::printf("[ weights ] largest sample weight %.2f\n", largest);
}

// ---------------------------------------------------------------------------------------------------------------------
// 3. Energy.

TEST(Brdf, WhiteFurnace) {
    // A white surface in a white furnace reflects all the light, at every roughness, metalness and view up to 89
    // degrees from the normal: between 0.97 and 1.01 (the goal; the albedo tables' resolution is what keeps it from
    // exactly 1, and it measures within about 0.002). The plain model (glTF Appendix B without compensation) is
    // what the tables correct: it loses the energy of multiple scattering (a rough white metal) and creates energy
    // at grazing views of a smooth dielectric (fresnel_mix's 1 - F(wo.h) keeps the diffuse lobe bright where the
    // interface already reflects nearly everything).
    double lowest = 2.0, highest = 0.0;
    Case argLow{}, argHigh{};
    for (float r : {0.f, 0.05f, 0.1f, 0.2f, 0.3f, 0.5f, 0.7f, 1.f}) {
        for (float m : {0.f, 0.5f, 1.f}) {
            for (float view : {0.f, 20.f, 40.f, 60.f, 75.f, 85.f, 89.f}) {
                const BrdfInputs in{glm::vec3(1.f), m, r};
                const Frame frame = makeFrame(kNormal);
                const glm::vec3 wo = direction(frame, view, 0.7f);
                const double albedo = albedoByQuadrature(in, frame, wo, 384, 192).x;
                EXPECT_GE(albedo, 0.97) << describe({r, m, view});
                EXPECT_LE(albedo, 1.01) << describe({r, m, view});
                if (albedo < lowest) lowest = albedo, argLow = {r, m, view};
                if (albedo > highest) highest = albedo, argHigh = {r, m, view};
            }
        }
    }
    std::printf("[ furnace ] white albedo from %.5f (%s) to %.5f (%s)\n", lowest, describe(argLow).c_str(), highest,
                describe(argHigh).c_str());

    const Frame frame = makeFrame(kNormal);
    BrdfInputs roughMetal{glm::vec3(1.f), 1.f, 1.f}, smoothDielectric{glm::vec3(1.f), 0.f, 0.05f};
    roughMetal.multiScatter = smoothDielectric.multiScatter = false;
    const double metal = albedoByQuadrature(roughMetal, frame, direction(frame, 80.f, 0.f)).x;
    const double dielectric = albedoByQuadrature(smoothDielectric, frame, direction(frame, 85.f, 0.f)).x;
    std::printf("[ furnace ] plain model: rough metal at 80 deg %.3f, smooth dielectric at 85 deg %.3f\n", metal,
                dielectric);
    EXPECT_LT(metal, 0.7);
    EXPECT_GT(dielectric, 1.3);
}

TEST(Brdf, PlainModelIsTheSpecification) {
    // multiScatter = false is glTF 2.0 Appendix B, written out here independently from its pseudo-code:
    //   metal_brdf      = conductor_fresnel(f0 = baseColor, bsdf = specular_brdf)
    //   dielectric_brdf = fresnel_mix(ior = 1.5, base = diffuse_brdf(baseColor), layer = specular_brdf)
    //   material        = mix(dielectric_brdf, metal_brdf, metallic)
    Pcg32 rng(17);
    const Frame frame = makeFrame(kNormal);
    for (int i = 0; i < 5000; ++i) {
        // Roughness from 0.2: sharper lobes amplify the float rounding of the directions beyond the tolerance.
        BrdfInputs in{glm::vec3(rng.uniform(), rng.uniform(), rng.uniform()), rng.uniform(),
                      0.2f + 0.8f * rng.uniform()};
        in.multiScatter = false;
        const glm::vec3 wo = direction(frame, 85.f * rng.uniform(), 2.f * kPi * rng.uniform());
        const glm::vec3 wi = direction(frame, 85.f * rng.uniform(), 2.f * kPi * rng.uniform());
        const double alpha = std::max(double(in.roughness) * in.roughness, 1e-3), a2 = alpha * alpha;
        const glm::dvec3 n(kNormal), v(wo), l(wi), h = glm::normalize(v + l);
        const double NdotL = glm::dot(n, l), NdotV = glm::dot(n, v), NdotH = glm::dot(n, h), VdotH = glm::dot(v, h);
        const double Vis =
            0.5 / (NdotL * std::sqrt(NdotV * NdotV * (1 - a2) + a2) + NdotV * std::sqrt(NdotL * NdotL * (1 - a2) + a2));
        const double dd = NdotH * NdotH * (a2 - 1) + 1;
        const double D = a2 / (kPiD * dd * dd);
        const double specular = Vis * D, w = std::pow(1 - std::fabs(VdotH), 5.0);
        const glm::dvec3 base(in.baseColor);
        const glm::dvec3 metal = specular * (base + (1.0 - base) * w);
        const double fr = 0.04 + 0.96 * w;
        const glm::dvec3 dielectric = (1 - fr) * base / kPiD + fr * specular;
        const glm::dvec3 expected = glm::mix(dielectric, metal, double(in.metallic));
        const glm::vec3 f = evalBrdf(in, kNormal, wo, wi);
        for (int k = 0; k < 3; ++k)
            ASSERT_NEAR(f[k], expected[k], 1e-3 * std::max(expected[k], 1e-2)) << i << " channel " << k;  // float
    }
}

TEST(Brdf, IorAndSpecularSetTheDielectricFresnel) {
    // KHR_materials_ior and KHR_materials_specular: f0 = min(((ior - 1) / (ior + 1))^2 specularColor, 1) specular,
    // f90 = specular; glTF's default is exactly 0.04 and 1.
    MaterialData d;
    EXPECT_EQ(dielectricF0(d), glm::vec3(0.04f));
    d.ior = 1.33f;
    EXPECT_NEAR(dielectricF0(d).x, (0.33 / 2.33) * (0.33 / 2.33), 1e-7);
    d.ior = 0.f;  // the extension's special value: a Fresnel term of 1
    EXPECT_EQ(dielectricF0(d), glm::vec3(1.f));
    d.ior = 2.5f;
    d.specularFactor = 0.5f;
    d.specularColorFactor = glm::vec3(0.f, 1.f, 20.f);
    const float f0 = (1.5f / 3.5f) * (1.5f / 3.5f);
    EXPECT_NEAR(dielectricF0(d).x, 0.f, 1e-7);
    EXPECT_NEAR(dielectricF0(d).y, 0.5f * f0, 1e-6);
    EXPECT_NEAR(dielectricF0(d).z, 0.5f, 1e-6);  // clamped to 1 before the factor

    // The energy compensation holds for any dielectric Fresnel: white dielectrics of ior 2.5 (f0 0.18), with a
    // coloured and weakened specular, and with no specular at all (pure Lambert) reflect all the light.
    const Frame frame = makeFrame(kNormal);
    struct Fresnel {
        glm::vec3 f0;
        float f90;
    };
    for (const Fresnel& fr : {Fresnel{glm::vec3(f0), 1.f}, Fresnel{glm::vec3(0.02f, 0.1f, 0.3f) * 0.7f, 0.7f},
                              Fresnel{glm::vec3(0.f), 0.f}}) {
        for (float r : {0.05f, 0.5f, 1.f}) {
            for (float view : {0.f, 60.f, 85.f}) {
                BrdfInputs in{glm::vec3(1.f), 0.f, r};
                in.specularF0 = fr.f0;
                in.specularF90 = fr.f90;
                const glm::dvec3 albedo = albedoByQuadrature(in, frame, direction(frame, view, 0.2f), 384, 192);
                for (int k = 0; k < 3; ++k) {
                    EXPECT_GE(albedo[k], 0.97) << "f0 " << fr.f0[k] << " roughness " << r << " view " << view;
                    EXPECT_LE(albedo[k], 1.01) << "f0 " << fr.f0[k] << " roughness " << r << " view " << view;
                }
            }
        }
    }
    // The plain model's Fresnel is f0 + (f90 - f0) (1 - wo.h)^5 with these values: head-on mirror reflection.
    BrdfInputs mirror{glm::vec3(0.f), 0.f, 0.f};
    mirror.specularF0 = glm::vec3(f0);
    mirror.multiScatter = false;
    const glm::vec3 n(0.f, 0.f, 1.f);
    const double headOn = albedoByQuadrature(mirror, makeFrame(n), n).x;
    EXPECT_NEAR(headOn, f0, 2e-3);
}

TEST(Brdf, CompensationIsTheMissingEnergy) {
    // Kulla and Conty's lobe returns exactly what single scattering loses: for a white metal (F = 1) the albedo of
    // the compensated BRDF minus the plain one is 1 - E(mu_o), and E(mu_o) is the plain model's own albedo.
    const Frame frame = makeFrame(kNormal);
    for (float r : {0.2f, 0.5f, 1.f}) {
        for (float view : {0.f, 45.f, 75.f}) {
            BrdfInputs in{glm::vec3(1.f), 1.f, r};
            const glm::vec3 wo = direction(frame, view, 0.3f);
            const double compensated = albedoByQuadrature(in, frame, wo).x;
            in.multiScatter = false;
            const double plain = albedoByQuadrature(in, frame, wo).x;
            const double e = ggxAlbedo(glm::dot(kNormal, wo), r).e;
            EXPECT_NEAR(plain, e, 3e-3) << "roughness " << r << " view " << view;
            EXPECT_NEAR(compensated - plain, 1.0 - e, 3e-3) << "roughness " << r << " view " << view;
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------------
// 4. Reciprocity.

TEST(Brdf, Reciprocity) {
    Pcg32 rng(99);
    const Frame frame = makeFrame(kNormal);
    for (int i = 0; i < 20000; ++i) {
        BrdfInputs in{glm::vec3(rng.uniform(), rng.uniform(), rng.uniform()), rng.uniform(),
                      i % 10 == 0 ? 0.f : rng.uniform()};
        in.multiScatter = i % 2 == 0;  // both models
        const glm::vec3 a = direction(frame, 89.f * rng.uniform(), 2.f * kPi * rng.uniform());
        const glm::vec3 b = direction(frame, 89.f * rng.uniform(), 2.f * kPi * rng.uniform());
        const glm::vec3 fab = evalBrdf(in, kNormal, a, b), fba = evalBrdf(in, kNormal, b, a);
        // 2e-5 relative: float rounding, amplified near 89 degrees where 1 - Fd(cos) cancels (the two orders round
        // differently, and how they round moves with the compiler's FMA contraction).
        for (int k = 0; k < 3; ++k) ASSERT_NEAR(fab[k], fba[k], 2e-5f * std::fmax(fab[k], 1e-3f)) << i;
    }
}

// ---------------------------------------------------------------------------------------------------------------------
// 5. Limits and normalisations.

TEST(Brdf, RoughWhiteDielectricIsNearlyLambertian) {
    // Roughness 1, plain model: a white Lambert lobe dimmed by what the interface reflects, plus a weak, flat
    // specular lobe: close to 1 and never above it for views up to 80 degrees.
    const Frame frame = makeFrame(kNormal);
    BrdfInputs in{glm::vec3(1.f), 0.f, 1.f};
    in.multiScatter = false;
    for (float view = 0.f; view <= 80.f; view += 10.f) {
        const double albedo = albedoByQuadrature(in, frame, direction(frame, view, 0.f)).x;
        EXPECT_GT(albedo, 0.85) << view;
        EXPECT_LE(albedo, 1.0) << view;
    }
}

TEST(Brdf, GgxNdfIsNormalized) {
    // Projected microfacet area equals the macro-surface: integral of D(h) (n.h) dh = 1 (Walter et al. 2007, eq. 4),
    // and the distribution of visible normals integrates to 1: integral of G1(wo) (wo.h)+ D(h) / (n.wo) dh = 1
    // (Heitz 2014, eq. 3), which checks G1 against D.
    for (float alpha : {1e-3f, 0.01f, 0.05f, 0.2f, 0.5f, 1.f}) {
        const double area =
            integrateOverHemisphere([&](glm::vec3 h) { return double(ggxD(h, alpha) * h.z); }, 1024, 64);
        EXPECT_NEAR(area, 1.0, 1e-3) << "alpha " << alpha;
        for (float view : {0.f, 45.f, 85.f}) {
            const float t = view * kPi / 180.f;
            const glm::vec3 wo(std::sin(t), 0.f, std::cos(t));
            const double visible = integrateOverHemisphere(
                [&](glm::vec3 h) {
                    return double(ggxG1(wo.z, alpha) * std::fmax(0.f, glm::dot(wo, h)) * ggxD(h, alpha) / wo.z);
                },
                1024, 256);
            EXPECT_NEAR(visible, 1.0, 2e-3) << "alpha " << alpha << " view " << view;
        }
    }
}

TEST(Brdf, SmoothLimitIsSchlickFresnel) {
    // As roughness -> 0 the specular lobe is a mirror with G ~ 1: its albedo is Schlick's F at the view angle. A black
    // dielectric and a coloured metal leave only that lobe.
    const Frame frame = makeFrame(kNormal);
    const glm::vec3 gold(1.f, 0.78f, 0.34f);
    for (float view = 0.f; view <= 80.f; view += 10.f) {
        const glm::vec3 wo = direction(frame, view, 1.3f);
        const float cosV = glm::dot(kNormal, wo);
        const glm::dvec3 metal = albedoByQuadrature({gold, 1.f, 0.f}, frame, wo);
        const glm::dvec3 black = albedoByQuadrature({glm::vec3(0.f), 0.f, 0.f}, frame, wo);
        const glm::vec3 fMetal = schlickFresnel(gold, cosV), fBlack = schlickFresnel(glm::vec3(kDielectricF0), cosV);
        for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(metal[k], fMetal[k], 2e-3) << view;
            EXPECT_NEAR(black[k], fBlack[k], 2e-3) << view;
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------------
// 6. Chi-square test of the sampled directions against pdfBrdf() (in the manner of Mitsuba's and pbrt's chi2 tests).

namespace {

/// Probability that a chi-square variable with `dof` degrees of freedom exceeds x is tiny when the Wilson-Hilferty
/// normal approximation (Wilson and Hilferty 1931) of x lies many standard deviations above the mean.
double wilsonHilfertyZ(double chi2, int dof) {
    const double k = dof;
    return (std::cbrt(chi2 / k) - (1.0 - 2.0 / (9.0 * k))) / std::sqrt(2.0 / (9.0 * k));
}

}  // namespace

TEST(Brdf, SampledDirectionsFollowPdf) {
    constexpr int kTheta = 12, kPhi = 24, kSub = 16, kSamples = 400000;
    const Case cases[] = {{0.5f, 0.f, 30.f}, {0.3f, 1.f, 60.f}, {0.7f, 0.5f, 80.f}};
    for (const Case& c : cases) {
        const BrdfInputs in{glm::vec3(0.7f, 0.6f, 0.5f), c.metallic, c.roughness};
        const Frame frame = makeFrame(kNormal);
        const glm::vec3 wo = direction(frame, c.viewDeg, 0.f);
        // Bins: equal steps of theta over the upper hemisphere and of phi, plus one bin for invalid samples (those
        // reflected below the surface), whose probability is what the upper hemisphere misses.
        std::vector<double> expected(kTheta * kPhi + 1, 0.0), observed(kTheta * kPhi + 1, 0.0);
        const double dTheta = 0.5 * kPiD / kTheta, dPhi = 2.0 * kPiD / kPhi;
        double upper = 0.0;
        for (int bt = 0; bt < kTheta; ++bt)
            for (int bp = 0; bp < kPhi; ++bp) {
                double p = 0.0;
                for (int i = 0; i < kSub; ++i)
                    for (int j = 0; j < kSub; ++j) {
                        const double theta = (bt + (i + 0.5) / kSub) * dTheta, phi = (bp + (j + 0.5) / kSub) * dPhi;
                        const glm::vec3 wl(float(std::sin(theta) * std::cos(phi)),
                                           float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)));
                        p += pdfBrdf(in, kNormal, wo, frame.toWorld(wl)) * std::sin(theta);
                    }
                p *= dTheta * dPhi / (kSub * kSub);
                expected[bt * kPhi + bp] = p * kSamples;
                upper += p;
            }
        expected.back() = std::max(0.0, 1.0 - upper) * kSamples;
        Pcg32 rng(77, uint64_t(c.viewDeg));
        for (int i = 0; i < kSamples; ++i) {
            const BrdfSample s = sampleBrdf(in, kNormal, wo, rng.uniform2(), rng.uniform());
            if (!s.valid) {
                observed.back() += 1.0;
                continue;
            }
            const glm::vec3 wl = frame.toLocal(s.wi);
            const double theta = std::acos(std::clamp(double(wl.z), -1.0, 1.0));
            double phi = std::atan2(double(wl.y), double(wl.x));
            if (phi < 0.0) phi += 2.0 * kPiD;
            const int bt = std::min(kTheta - 1, int(theta / dTheta)), bp = std::min(kPhi - 1, int(phi / dPhi));
            observed[bt * kPhi + bp] += 1.0;
        }
        // Pool bins expecting fewer than 5 samples, as the chi-square approximation requires.
        double chi2 = 0.0, pooledExpected = 0.0, pooledObserved = 0.0;
        int bins = 0;
        for (size_t b = 0; b < expected.size(); ++b) {
            if (expected[b] < 5.0) {
                pooledExpected += expected[b];
                pooledObserved += observed[b];
                continue;
            }
            chi2 += (observed[b] - expected[b]) * (observed[b] - expected[b]) / expected[b];
            ++bins;
        }
        if (pooledExpected >= 5.0) {
            chi2 += (pooledObserved - pooledExpected) * (pooledObserved - pooledExpected) / pooledExpected;
            ++bins;
        } else {
            EXPECT_LT(pooledObserved, 5.0 + 5.0 * std::sqrt(5.0)) << describe(c);
        }
        const double z = wilsonHilfertyZ(chi2, bins - 1);
        // z = 4.5 is a p-value of about 3e-6: a correct sampler essentially never fails, a biased one does.
        EXPECT_LT(z, 4.5) << describe(c) << ": chi2 " << chi2 << " with " << bins - 1 << " dof";
        std::printf("[ chi2 ] %s: chi2 %.1f, %d dof, z %.2f\n", describe(c).c_str(), chi2, bins - 1, z);
    }
}

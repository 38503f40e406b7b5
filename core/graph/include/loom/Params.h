#pragma once
// Typed parameter declarations: declared once per pass, bound to the pass's
// own members. They are the single source of truth for JSON parsing,
// validation, the viewer's UI and the generated pass reference.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <nlohmann/json_fwd.hpp>

namespace loom {

enum class ParamType { Bool, Int, Float, Enum, String, Vec3, Vec4 };

const char* paramTypeName(ParamType t);

/// A standard meaning a parameter can declare, so a tool that drives passes it does not know (`loom bench`) asks
/// for "the parameter that plays this role" instead of a pass type and a parameter name. A pass gives a role to
/// at most one of its parameters.
enum class ParamRole : uint8_t {
    None,
    SampleCount,  ///< int >= 1: samples per pixel per frame; the output is their mean
    Seed,         ///< int: decorrelates the random numbers of runs that share frame indices
    AutoReset,    ///< bool, of a pass that accumulates frames: true restarts the running mean when the view changes
    MaxBounces,   ///< int >= 0: scattering events per path of a path tracer
    RussianRouletteStart,  ///< int >= 0: the bounce from which a path tracer's Russian roulette may end paths
    PixelFilter,           ///< enum with the values kPixelFilterCenter and kPixelFilterBox: where camera samples start
};

/// The values of a ParamRole::PixelFilter parameter every pass that declares the role accepts: every sample at the
/// (jittered) pixel centre, or each sample uniformly in the pixel (camera jitter ignored).
inline constexpr char kPixelFilterCenter[] = "center";
inline constexpr char kPixelFilterBox[] = "box";

/// "sampleCount", "seed", "autoReset", "maxBounces", "russianRouletteStart", "pixelFilter" ("" for None).
const char* paramRoleName(ParamRole r);

struct ParamDecl {
    std::string name;
    ParamType type = ParamType::Float;
    std::string doc;
    std::optional<double> min, max;       ///< inclusive range for Int, Float (and each Vec component)
    std::vector<std::string> enumValues;  ///< for Enum: the accepted strings, index = value

    // Bound storage: how to read and write the member as JSON. Set by ParamList::add.
    std::function<nlohmann::json()> get;
    std::function<void(const nlohmann::json&)> set;
    std::function<nlohmann::json()> defaultValue;

    ParamRole role = ParamRole::None;  ///< the standard meaning it declares, if any
};

/// Chained setters on a declaration.
class ParamBuilder {
public:
    explicit ParamBuilder(ParamDecl& d) : mDecl(d) {}
    ParamBuilder& range(double lo, double hi) { mDecl.min = lo; mDecl.max = hi; return *this; }
    ParamBuilder& min(double lo) { mDecl.min = lo; return *this; }
    ParamBuilder& doc(std::string text) { mDecl.doc = std::move(text); return *this; }
    ParamBuilder& role(ParamRole r) { mDecl.role = r; return *this; }

private:
    ParamDecl& mDecl;
};

/// A pass's parameters, bound to its members. Assigning the default happens
/// at declaration.
class ParamList {
public:
    ParamBuilder add(std::string name, bool* member, bool def);
    ParamBuilder add(std::string name, int* member, int def);
    /// An int that is never negative (min 0 unless a range says more), for a kernel struct's unsigned member.
    ParamBuilder add(std::string name, uint32_t* member, uint32_t def);
    ParamBuilder add(std::string name, float* member, float def);
    ParamBuilder add(std::string name, std::string* member, std::string def);
    ParamBuilder add(std::string name, glm::vec3* member, glm::vec3 def);
    ParamBuilder add(std::string name, glm::vec4* member, glm::vec4 def);
    /// An enum given in JSON as one of `values`; the member holds the index.
    template <class E>
    ParamBuilder addEnum(std::string name, E* member, E def, std::vector<std::string> values) {
        return addEnumImpl(
            std::move(name), [member] { return int(*member); }, [member](int v) { *member = E(v); }, int(def),
            std::move(values));
    }

    const std::vector<ParamDecl>& decls() const { return mDecls; }
    const ParamDecl* find(const std::string& name) const;
    /// The parameter that plays `role`, or nullptr.
    const ParamDecl* findRole(ParamRole role) const;

    /// Validates and assigns. Throws loom::Error (BadInput) naming `where`
    /// (e.g. "/passes/1/params/alpha" or "SVGF.alpha") for an unknown name
    /// (with did-you-mean), a wrong type or an out-of-range value.
    void set(const std::string& name, const nlohmann::json& value, const std::string& where);
    /// Assigns every key of a JSON object; `where` is the object's JSON path.
    void setAll(const nlohmann::json& object, const std::string& where);
    nlohmann::json get(const std::string& name) const;
    /// All values (or only those that differ from their default) as a JSON object.
    nlohmann::json toJson(bool onlyNonDefault) const;
    /// What is wrong with the declarations themselves, or empty: a name that is not plain, a name declared twice,
    /// an empty or non-finite range, an enum without values, a default outside its own range or values, a role
    /// given twice or to a parameter of another type than the role's (or, for PixelFilter, without its values).
    std::string declarationProblem() const;

private:
    ParamBuilder addEnumImpl(std::string name, std::function<int()> get, std::function<void(int)> set, int def,
                             std::vector<std::string> values);
    ParamDecl& push(std::string name, ParamType type);
    std::vector<ParamDecl> mDecls;
};

/// Parses a command-line value ("3", "0.5", "true", "aces", "[1,2,3]") into
/// JSON: JSON syntax when it parses, else a string.
nlohmann::json parseParamValue(const std::string& text);

}  // namespace loom

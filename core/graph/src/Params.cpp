#include "loom/Params.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>

#include "loom/Error.h"
#include "loom/InputFile.h"

namespace loom {

using json = nlohmann::json;

const char* paramTypeName(ParamType t) {
    switch (t) {
        case ParamType::Bool: return "bool";
        case ParamType::Int: return "int";
        case ParamType::Float: return "float";
        case ParamType::Enum: return "enum";
        case ParamType::String: return "string";
        case ParamType::Vec3: return "vec3";
        case ParamType::Vec4: return "vec4";
    }
    return "?";
}

const char* paramRoleName(ParamRole r) {
    switch (r) {
        case ParamRole::None: return "";
        case ParamRole::SampleCount: return "sampleCount";
        case ParamRole::Seed: return "seed";
        case ParamRole::AutoReset: return "autoReset";
        case ParamRole::MaxBounces:
            return "maxBounces";
        case ParamRole::RussianRouletteStart:
            return "russianRouletteStart";
        case ParamRole::PixelFilter:
            return "pixelFilter";
    }
    return "?";
}

ParamDecl& ParamList::push(std::string name, ParamType type) {
    ParamDecl d;
    d.name = std::move(name);
    d.type = type;
    mDecls.push_back(std::move(d));
    return mDecls.back();
}

ParamBuilder ParamList::add(std::string name, bool* member, bool def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Bool);
    d.get = [member] { return json(*member); };
    d.set = [member](const json& v) { *member = v.get<bool>(); };
    d.defaultValue = [def] { return json(def); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, int* member, int def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Int);
    d.get = [member] { return json(*member); };
    d.set = [member](const json& v) { *member = v.get<int>(); };
    d.defaultValue = [def] { return json(def); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, uint32_t* member, uint32_t def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Int);
    d.min = 0.0;
    d.get = [member] { return json(*member); };
    d.set = [member](const json& v) { *member = v.get<uint32_t>(); };
    d.defaultValue = [def] { return json(def); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, float* member, float def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Float);
    d.get = [member] { return json(*member); };
    d.set = [member](const json& v) { *member = v.get<float>(); };
    d.defaultValue = [def] { return json(def); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, std::string* member, std::string def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::String);
    d.get = [member] { return json(*member); };
    d.set = [member](const json& v) { *member = v.get<std::string>(); };
    d.defaultValue = [def] { return json(def); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, glm::vec3* member, glm::vec3 def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Vec3);
    d.get = [member] { return json::array({member->x, member->y, member->z}); };
    d.set = [member](const json& v) { *member = {v[0].get<float>(), v[1].get<float>(), v[2].get<float>()}; };
    d.defaultValue = [def] { return json::array({def.x, def.y, def.z}); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::add(std::string name, glm::vec4* member, glm::vec4 def) {
    *member = def;
    auto& d = push(std::move(name), ParamType::Vec4);
    d.get = [member] { return json::array({member->x, member->y, member->z, member->w}); };
    d.set = [member](const json& v) {
        *member = {v[0].get<float>(), v[1].get<float>(), v[2].get<float>(), v[3].get<float>()};
    };
    d.defaultValue = [def] { return json::array({def.x, def.y, def.z, def.w}); };
    return ParamBuilder(d);
}

ParamBuilder ParamList::addEnumImpl(std::string name, std::function<int()> get, std::function<void(int)> set, int def,
                                    std::vector<std::string> values) {
    set(def);
    auto& d = push(std::move(name), ParamType::Enum);
    d.enumValues = std::move(values);
    auto names = d.enumValues;
    d.get = [get, names] {
        const int i = get();
        return i >= 0 && size_t(i) < names.size() ? json(names[size_t(i)]) : json();
    };
    d.set = [set, names](const json& v) {
        const auto s = v.get<std::string>();
        for (size_t i = 0; i < names.size(); ++i)
            if (names[i] == s) set(int(i));
    };
    // An index outside the values is a faulty declaration: declarationProblem() reports it, so nothing throws here.
    const bool valid = def >= 0 && size_t(def) < d.enumValues.size();
    std::string defName = valid ? d.enumValues[size_t(def)] : std::string();
    d.defaultValue = [defName, valid] { return valid ? json(defName) : json(); };
    return ParamBuilder(d);
}

const ParamDecl* ParamList::find(const std::string& name) const {
    for (const auto& d : mDecls)
        if (d.name == name) return &d;
    return nullptr;
}

const ParamDecl* ParamList::findRole(ParamRole role) const {
    for (const auto& d : mDecls)
        if (role != ParamRole::None && d.role == role) return &d;
    return nullptr;
}

namespace {

/// The type of the parameters that may play `role` (not None).
ParamType roleType(ParamRole role) {
    switch (role) {
        case ParamRole::AutoReset:
            return ParamType::Bool;
        case ParamRole::PixelFilter:
            return ParamType::Enum;
        case ParamRole::None:
        case ParamRole::SampleCount:
        case ParamRole::Seed:
        case ParamRole::MaxBounces:
        case ParamRole::RussianRouletteStart:
            break;
    }
    return ParamType::Int;
}

std::vector<std::string> declNames(const std::vector<ParamDecl>& decls) {
    std::vector<std::string> out;
    for (const auto& d : decls) out.push_back(d.name);
    return out;
}

std::string rangeText(const ParamDecl& d) {
    if (d.min && d.max) return fmt::format("a value in [{}, {}]", *d.min, *d.max);
    if (d.min) return fmt::format("a value >= {}", *d.min);
    if (d.max) return fmt::format("a value <= {}", *d.max);
    return "a value";
}

void checkNumber(const ParamDecl& d, const json& v, const std::string& where, bool integer) {
    if (!v.is_number() || (integer && !v.is_number_integer())) {
        throwBadInput(
            where,
            "parameter '" + d.name + "' has the wrong type: got " + std::string(v.type_name()) + " " + jsonExcerpt(v),
            integer ? "an integer" : "a number");
    }
    double x = v.get<double>();
    if (!std::isfinite(x)) throwBadInput(where, "parameter '" + d.name + "' is not finite", "a finite number");
    if ((d.min && x < *d.min) || (d.max && x > *d.max)) {
        throwBadInput(where, fmt::format("parameter '{}' is out of range: {}", d.name, jsonExcerpt(v)), rangeText(d),
                      "the documented range is in docs/PASSES.md (`loom passes`)");
    }
    if (integer && (x < double(INT32_MIN) || x > double(INT32_MAX)))
        throwBadInput(where, "parameter '" + d.name + "' does not fit a 32-bit integer", "a smaller integer");
    // A finite double can still overflow the float member (1e300 would be stored as inf).
    if (!integer && std::fabs(x) > double(std::numeric_limits<float>::max()))
        throwBadInput(where, "parameter '" + d.name + "' does not fit a 32-bit float", "a smaller number");
}

}  // namespace

void ParamList::set(const std::string& name, const json& value, const std::string& where) {
    const ParamDecl* d = find(name);
    if (!d) {
        throwBadInput(where, "unknown parameter '" + name + "'", "one of: " + join(declNames(mDecls)),
                      didYouMean(name, declNames(mDecls), ""));
    }
    switch (d->type) {
        case ParamType::Bool:
            if (!value.is_boolean())
                throwBadInput(where, "parameter '" + name + "' has the wrong type: got " + jsonExcerpt(value),
                              "true or false");
            break;
        case ParamType::Int: checkNumber(*d, value, where, true); break;
        case ParamType::Float: checkNumber(*d, value, where, false); break;
        case ParamType::String:
            if (!value.is_string())
                throwBadInput(where, "parameter '" + name + "' has the wrong type: got " + jsonExcerpt(value),
                              "a string");
            break;
        case ParamType::Enum: {
            if (!value.is_string())
                throwBadInput(where, "parameter '" + name + "' has the wrong type: got " + jsonExcerpt(value),
                              "one of: " + join(d->enumValues));
            const auto s = value.get<std::string>();
            if (std::find(d->enumValues.begin(), d->enumValues.end(), s) == d->enumValues.end())
                throwBadInput(where, "parameter '" + name + "' has no value '" + s + "'",
                              "one of: " + join(d->enumValues), didYouMean(s, d->enumValues, ""));
            break;
        }
        case ParamType::Vec3:
        case ParamType::Vec4: {
            size_t n = d->type == ParamType::Vec3 ? 3 : 4;
            if (!value.is_array() || value.size() != n)
                throwBadInput(where, "parameter '" + name + "' has the wrong type: got " + jsonExcerpt(value),
                              fmt::format("an array of {} numbers", n));
            for (const auto& c : value) checkNumber(*d, c, where, false);
            break;
        }
    }
    d->set(value);
}

void ParamList::setAll(const json& object, const std::string& where) {
    if (!object.is_object())
        throwBadInput(where, "params must be an object, got " + std::string(object.type_name()),
                      "{\"name\": value, ...}");
    for (auto it = object.begin(); it != object.end(); ++it) set(it.key(), it.value(), where + "/" + it.key());
}

json ParamList::get(const std::string& name) const {
    const ParamDecl* d = find(name);
    return d ? d->get() : json();
}

json ParamList::toJson(bool onlyNonDefault) const {
    json out = json::object();
    for (const auto& d : mDecls) {
        json v = d.get();
        if (!onlyNonDefault || v != d.defaultValue()) out[d.name] = std::move(v);
    }
    return out;
}

std::string ParamList::declarationProblem() const {
    std::set<std::string> seen;
    for (const auto& d : mDecls) {
        const std::string name = "parameter '" + printable(d.name) + "'";
        if (!isPlainName(d.name)) return name + " does not have a plain name (a letter or _, then letters, digits, _)";
        if (!seen.insert(d.name).second) return name + " is declared twice";
        const bool numeric = d.type == ParamType::Int || d.type == ParamType::Float || d.type == ParamType::Vec3 ||
                             d.type == ParamType::Vec4;
        if ((d.min && !std::isfinite(*d.min)) || (d.max && !std::isfinite(*d.max)) || (d.min && d.max && *d.min > *d.max))
            return name + " has an empty or non-finite range";
        if (d.type == ParamType::Enum) {
            if (d.enumValues.empty()) return name + " is an enum without values";
            if (std::set<std::string>(d.enumValues.begin(), d.enumValues.end()).size() != d.enumValues.size())
                return name + " lists an enum value twice";
            if (!d.defaultValue().is_string()) return name + " has a default outside its enum values";
        }
        if (d.role != ParamRole::None) {
            const ParamType wanted = roleType(d.role);
            if (d.type != wanted)
                return fmt::format("{} plays the role {}, which needs a parameter of type {}", name,
                                   paramRoleName(d.role), paramTypeName(wanted));
            const auto hasValue = [&](const char* v) {
                return std::find(d.enumValues.begin(), d.enumValues.end(), v) != d.enumValues.end();
            };
            if (d.role == ParamRole::PixelFilter && !(hasValue(kPixelFilterCenter) && hasValue(kPixelFilterBox)))
                return fmt::format("{} plays the role {}, whose values include '{}' and '{}'", name,
                                   paramRoleName(d.role), kPixelFilterCenter, kPixelFilterBox);
            if (const ParamDecl* first = findRole(d.role); first != &d)
                return fmt::format("{} plays the role {}, which parameter '{}' already plays", name,
                                   paramRoleName(d.role), printable(first->name));
        }
        if (!numeric) continue;
        const json def = d.defaultValue();
        std::vector<double> values;
        if (def.is_array()) {
            for (const auto& c : def) values.push_back(c.get<double>());
        } else {
            values.push_back(def.get<double>());
        }
        for (double x : values)
            if (!std::isfinite(x) || (d.min && x < *d.min) || (d.max && x > *d.max))
                return fmt::format("{} has the default {}, outside its own range ({})", name, def.dump(), rangeText(d));
    }
    return {};
}

json parseParamValue(const std::string& text) {
    // Nesting is checked (what parses is copied and printed recursively); a number beyond a double does not parse
    // and is taken as the string it is, which the parameter's type check then reports.
    checkJsonText(text, "the value '" + printable(text.substr(0, 40)) + "'", false);
    json v = json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (v.is_discarded()) return json(text);
    return v;
}

}  // namespace loom

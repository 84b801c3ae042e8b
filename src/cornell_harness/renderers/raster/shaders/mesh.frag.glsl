#version 330 core
// Lambertian direct lighting from one-sided cosine point lights, in float.
const float PI = 3.141592653589793;
const float DIST_SCALE = @DIST_SCALE@;    // K: the shadow map stores d/(d+K)
const float TEXEL_ANGLE = @TEXEL_ANGLE@;  // largest angle one shadow-map texel subtends
const float SLOPE_BIAS = @SLOPE_BIAS@;        // in texels per unit tan(theta_r)
const float CONST_BIAS = @CONST_BIAS@;        // in texels

struct SpotLight {
    vec3 color;        // radiance L of the emitter
    float intensity;   // area of the emitter piece: I(theta) = color*intensity*cos(theta)
    vec3 position;
    vec3 direction;    // emitter normal
#ifdef SPOT_LIGHT_SHADOWS
    sampler2D shadow_map;
    mat4 light_matrix;
#endif
};
struct Material {
    vec3 emissive_factor;
    vec4 base_color_factor;
};

uniform Material material;
uniform SpotLight spot_lights[MAX_SPOT_LIGHTS];
uniform int n_spot_lights;

centroid in vec3 frag_position;
centroid in vec3 frag_normal;
out vec4 frag_color;

#ifdef SPOT_LIGHT_SHADOWS
float stored_distance(int i, ivec2 texel, ivec2 size)
{
    texel = clamp(texel, ivec2(0), size - 1);
    float s = texelFetch(spot_lights[i].shadow_map, texel, 0).r;
    return s >= 1.0 ? 3.0e38 : DIST_SCALE * s / (1.0 - s);
}

float visibility(int i, vec3 p, float dist, float cos_r, float cos_l)
{
    // Size of a shadow-map texel on a surface facing the light at this point
    // (texels subtend less than TEXEL_ANGLE away from the map's centre).
    float texel = dist * TEXEL_ANGLE * cos_l;
    float tan_r = min(sqrt(max(0.0, 1.0 - cos_r * cos_r)) / cos_r, 8.0);
    vec4 c = spot_lights[i].light_matrix * vec4(p, 1.0);
    if (c.w <= 0.0) return 1.0;
    vec2 uv = c.xy / c.w * 0.5 + 0.5;
    if (uv.x < 0.0 || uv.y < 0.0 || uv.x > 1.0 || uv.y > 1.0) return 1.0;  // outside the map
    // Slope-scaled bias: neighbouring texels see the surface up to ~texel*tan_r nearer.
    float d = dist - texel * (SLOPE_BIAS * tan_r + CONST_BIAS);
    ivec2 size = textureSize(spot_lights[i].shadow_map, 0);
    vec2 f = uv * vec2(size) - 0.5;
    ivec2 t = ivec2(floor(f));
    vec2 w = f - floor(f);
    float v00 = d <= stored_distance(i, t, size) ? 1.0 : 0.0;
    float v10 = d <= stored_distance(i, t + ivec2(1, 0), size) ? 1.0 : 0.0;
    float v01 = d <= stored_distance(i, t + ivec2(0, 1), size) ? 1.0 : 0.0;
    float v11 = d <= stored_distance(i, t + ivec2(1, 1), size) ? 1.0 : 0.0;
    return mix(mix(v00, v10, w.x), mix(v01, v11, w.x), w.y);
}
#endif

void main()
{
    vec3 n = normalize(frag_normal);
    vec3 lo = vec3(0.0);
    for (int i = 0; i < n_spot_lights; i++) {
        vec3 to_light = spot_lights[i].position - frag_position;
        float dist = length(to_light);
        vec3 l = to_light / dist;
        float cos_r = dot(n, l);
        float cos_l = -dot(spot_lights[i].direction, l);
        if (cos_r <= 0.0 || cos_l <= 0.0) continue;
        float v = 1.0;
#ifdef SPOT_LIGHT_SHADOWS
        v = visibility(i, frag_position, dist, cos_r, cos_l);
#endif
        lo += spot_lights[i].color * (spot_lights[i].intensity * cos_l * cos_r * v / (dist * dist));
    }
    frag_color = vec4(material.base_color_factor.rgb / PI * lo + material.emissive_factor, 1.0);
}

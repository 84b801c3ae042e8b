#version 330 core
layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;
uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
// centroid: with MSAA, a partly covered pixel must not shade a point off the triangle.
centroid out vec3 frag_position;
centroid out vec3 frag_normal;
void main()
{
    mat4 W = M * inst_m;
    vec4 wp = W * vec4(position, 1.0);
    gl_Position = P * V * wp;
    frag_position = wp.xyz;
#ifdef NORMAL_LOC
    frag_normal = normalize(mat3(transpose(inverse(W))) * normal);
#else
    frag_normal = vec3(0.0);
#endif
}

#version 330 core
layout(location = 0) in vec3 position;
layout(location = INST_M_LOC) in mat4 inst_m;
uniform mat4 P;
uniform mat4 V;
uniform mat4 M;
out vec3 eye_position;
void main()
{
    vec4 e = V * M * inst_m * vec4(position, 1.0);
    eye_position = e.xyz;
    gl_Position = P * e;
}

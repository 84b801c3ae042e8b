#version 330 core
// Shadow map: distance to the light (the eye), stored as d/(d+K) in [0, 1).
const float DIST_SCALE = @DIST_SCALE@;
in vec3 eye_position;
out vec4 frag_color;
void main()
{
    float d = length(eye_position);
    gl_FragDepth = d / (d + DIST_SCALE);
    frag_color = vec4(1.0);
}

// Which patches a draw phase keeps, from the occlusion state the test in
// occlusion.comp leaves per patch (OCCLUSION_*_BIT). Phase
// OCCLUSION_PHASE_ALL keeps every patch: occlusion is off.

layout(std430, set = 0, binding = BINDING_VISIBILITY) readonly buffer Visibility {
    uint visibility[];
};

bool drawn_in_phase(uint phase, int patch_index) {
    if (phase == OCCLUSION_PHASE_ALL) {
        return true;
    }
    uint bit = phase == OCCLUSION_PHASE_FIRST ? OCCLUSION_VISIBLE_BIT
        : phase == OCCLUSION_PHASE_SECOND ? OCCLUSION_NEWLY_VISIBLE_BIT
        : OCCLUSION_CULLED_BIT;
    return (visibility[patch_index] & bit) != 0u;
}

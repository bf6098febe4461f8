/* A point light whose intensity falls off as 1/distance^decay, as Maya's lights (and their
 * exporters' light shaders, e.g. Liquid's liquidpoint) define it: decay 0 is no falloff,
 * 1 linear, 2 quadratic (RISpec's pointlight). arbor stands it in for a missing light shader
 * whose instance gives a "decay". */
light pointlight_decay(float intensity = 1; color lightcolor = 1;
                       point from = point "shader" (0, 0, 0);
                       float decay = 2;)
{
    illuminate(from)
        Cl = intensity * lightcolor / pow(L . L, decay / 2);
}

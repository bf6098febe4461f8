/* RISpec 3.2 Appendix A: ambientlight */
light ambientlight(float intensity = 1; color lightcolor = 1;)
{
    Cl = intensity * lightcolor;
}

/* RISpec 3.2 Appendix A: bumpy (Appendix A's source names the amplitude Km) */
displacement bumpy(float Km = 1; string texturename = "";)
{
    float amp = 0;
    if (texturename != "")
        amp = Km * float texture(texturename, s, t);
    P += amp * normalize(N);
    N = calculatenormal(P);
}

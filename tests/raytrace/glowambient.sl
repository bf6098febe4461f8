/* A glow of 0.5 plus half the ambient light: what ambient() returns is read off the picture. */
surface glowambient()
{
    Ci = 0.5 + 0.5 * ambient();
    Oi = 1;
}

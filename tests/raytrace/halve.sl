/* A volume that lets half the light through. */
volume halve()
{
    Ci *= 0.5;
}

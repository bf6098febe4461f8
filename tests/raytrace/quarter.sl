/* A volume that lets a quarter of the light through. */
volume quarter()
{
    Ci *= 0.25;
}

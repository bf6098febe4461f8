surface
constant()
{
    Oi = Os;
    Ci = Os * Cs;
}

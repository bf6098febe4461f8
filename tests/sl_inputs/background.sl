imager
background(
    color background = 1;)
{
    Ci += (1 - alpha) * background;
    Oi = 1;
    alpha = 1;
}

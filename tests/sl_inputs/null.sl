surface
null()
{
}

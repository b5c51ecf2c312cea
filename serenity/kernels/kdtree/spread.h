// Morton spreads by shifts and masks, for x an unsigned int or a vector of ints whose bits above
// the 5th are 0: SPREAD3 moves bit b of x to bit 3b (one axis' share of a 3-D Morton code),
// SPREAD2 to bit 2b (one coordinate's share of a 2-D one). Included inside a native's body.
#define SPREAD3(x)                               \
    do {                                         \
        x = (x | (x << 16)) & 0x030000FF;        \
        x = (x | (x << 8)) & 0x0300F00F;         \
        x = (x | (x << 4)) & 0x030C30C3;         \
        x = (x | (x << 2)) & 0x09249249;         \
    } while (0)
#define SPREAD2(x)                               \
    do {                                         \
        x = (x | (x << 8)) & 0x00FF00FF;         \
        x = (x | (x << 4)) & 0x0F0F0F0F;         \
        x = (x | (x << 2)) & 0x33333333;         \
        x = (x | (x << 1)) & 0x55555555;         \
    } while (0)

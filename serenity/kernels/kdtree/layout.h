// The traversal's loads from the tree's arrays (layout.py): element i of a contiguous array at
// data + i * sizeof(element), a compile-time size, without Warp's run-time stride multiply and
// negative-index wrap (the traversal's chain of dependent loads: node, next node, ...). i must be
// in range. Portable: CPU and CUDA.

int node_head(wp::array_t<KdNode> nodes, int i)
{
    return nodes.data[(unsigned)i].head;
}

float node_split(wp::array_t<KdNode> nodes, int i)
{
    return nodes.data[(unsigned)i].split;
}

wp::vec3 ref_vertex(wp::array_t<float> refs, int i, int k)
{
    const float* p = refs.data + (unsigned)i;
    return wp::vec3(p[0], p[k], p[2 * k]);
}

int ref_prim(wp::array_t<float> refs, int i)
{
    return ((const int*)refs.data)[(unsigned)i];
}

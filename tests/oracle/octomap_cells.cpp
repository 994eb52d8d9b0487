// Lists the occupied leaves of a .bt file as liboctomap reads it, one per line:
// "min_index_x min_index_y min_index_z side" (index = OctoMap's getIndexKey() - 32768,
// side = cells per axis), then "nodes N res R" last. The oracle of
// tests/tests/octomap.rs: OctoMap's own reader, not ours.
#include <octomap/OcTree.h>
#include <cstdio>

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: octomap_cells FILE.bt\n");
        return 2;
    }
    octomap::OcTree tree(0.1);
    if (!tree.readBinary(argv[1])) {
        std::fprintf(stderr, "liboctomap could not read %s\n", argv[1]);
        return 1;
    }
    for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
        if (!tree.isNodeOccupied(*it)) continue;
        octomap::OcTreeKey k = it.getIndexKey();
        long side = 1L << (tree.getTreeDepth() - it.getDepth());
        std::printf("%ld %ld %ld %ld\n", long(k[0]) - 32768, long(k[1]) - 32768, long(k[2]) - 32768, side);
    }
    std::printf("nodes %zu res %.17g\n", tree.size(), tree.getResolution());
    return 0;
}

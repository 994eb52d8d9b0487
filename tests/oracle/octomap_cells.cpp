// liboctomap as the oracle of tests/tests/it/octomap.rs: OctoMap's own reader and writer,
// not ours.
//
//   octomap_cells FILE.bt
//     lists the occupied leaves as liboctomap reads them, one per line:
//     "min_index_x min_index_y min_index_z side" (index = getIndexKey() - 32768, side =
//     cells per axis), then "nodes N res R" last.
//   octomap_cells generate OUT.bt RES SEED pruned|unpruned
//     writes a map of random occupied and free cells and solid 2^n blocks (which pruning
//     turns into nodes above the finest depth), pruned (writeBinary) or not
//     (writeBinaryConst).
#include <octomap/OcTree.h>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>

static int list(const char* path) {
    octomap::OcTree tree(0.1);
    if (!tree.readBinary(path)) {
        std::fprintf(stderr, "liboctomap could not read %s\n", path);
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

static int generate(const char* out, double res, unsigned seed, bool pruned) {
    octomap::OcTree tree(res);
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> cell(32768 - 40, 32768 + 40);
    std::uniform_int_distribution<int> coin(0, 3);
    auto set = [&](int x, int y, int z, bool occupied) {
        octomap::OcTreeKey key(x, y, z);
        tree.updateNode(key, occupied, true);
    };
    for (int i = 0; i < 3000; ++i) set(cell(rng), cell(rng), cell(rng), coin(rng) != 0);
    // Solid blocks aligned to their size: pruned, each is one node above depth 16.
    for (int side : {2, 4, 8}) {
        int x = (cell(rng) / side) * side, y = (cell(rng) / side) * side, z = (cell(rng) / side) * side;
        for (int i = 0; i < side; ++i)
            for (int j = 0; j < side; ++j)
                for (int k = 0; k < side; ++k) set(x + i, y + j, z + k, true);
    }
    tree.updateInnerOccupancy();
    bool ok = pruned ? tree.writeBinary(out) : tree.writeBinaryConst(out);
    return ok ? 0 : 1;
}

int main(int argc, char** argv) {
    if (argc == 2) return list(argv[1]);
    if (argc == 6 && std::strcmp(argv[1], "generate") == 0)
        return generate(argv[2], std::atof(argv[3]), unsigned(std::atoi(argv[4])), std::strcmp(argv[5], "pruned") == 0);
    std::fprintf(stderr, "usage: octomap_cells FILE.bt | octomap_cells generate OUT.bt RES SEED pruned|unpruned\n");
    return 2;
}

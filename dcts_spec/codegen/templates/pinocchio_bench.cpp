// pinocchio_bench.cpp — reference timing for `dcts bench`: Pinocchio's numeric dynamics terms
// (computeAllTerms: M, nonlinear effects, joint Jacobians, ...) plus the task frames' Jacobians,
// on the same states as the generated controller. Written for dcts-spec; not part of a bundle.
//
//   pinocchio_bench MODEL.bin STATES OUT FRAME...
//
// MODEL.bin: the exact pinocchio::Model the controller was compiled from (Model.saveToBinary).
// STATES: as for <name>_bench (int32 count, then count × (q, dq, tau_ext, ref)); NREF via env
// DCTS_NREF. OUT: int64 ns per state.
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/serialization.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

int main(int argc, char **argv)
{
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s MODEL.bin STATES OUT FRAME...\n", argv[0]);
        return 2;
    }
    pinocchio::Model model;
    model.loadFromBinary(argv[1]);
    pinocchio::Data data(model);
    const int nq = model.nq, nv = model.nv;
    const int nref = std::getenv("DCTS_NREF") ? std::atoi(std::getenv("DCTS_NREF")) : 0;
    const int row = nq + 2 * nv + nref;

    std::FILE *in = std::fopen(argv[2], "rb");
    int32_t count = 0;
    if (!in || std::fread(&count, sizeof(count), 1, in) != 1 || count <= 0) return 2;
    std::vector<double> states(static_cast<size_t>(count) * row);
    if (std::fread(states.data(), sizeof(double) * row, count, in) != static_cast<size_t>(count)) return 2;
    std::fclose(in);

    std::vector<pinocchio::FrameIndex> frames;
    for (int i = 4; i < argc; ++i) frames.push_back(model.getFrameId(argv[i]));
    std::vector<pinocchio::Data::Matrix6x> jacobians(frames.size(), pinocchio::Data::Matrix6x::Zero(6, nv));
    std::vector<int64_t> ns(count);
    double sink = 0.0;

    for (int pass = 0; pass < 2; ++pass) {
        for (int k = 0; k < count; ++k) {
            Eigen::Map<const Eigen::VectorXd> q(&states[static_cast<size_t>(k) * row], nq);
            Eigen::Map<const Eigen::VectorXd> v(&states[static_cast<size_t>(k) * row + nq], nv);
            auto t0 = std::chrono::steady_clock::now();
            pinocchio::computeAllTerms(model, data, q, v);
            for (size_t f = 0; f < frames.size(); ++f)
                pinocchio::getFrameJacobian(model, data, frames[f], pinocchio::LOCAL_WORLD_ALIGNED, jacobians[f]);
            auto t1 = std::chrono::steady_clock::now();
            ns[k] = std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count();
            sink += data.M(0, 0) + (frames.empty() ? 0.0 : jacobians[0](0, 0));
        }
    }
    std::FILE *out = std::fopen(argv[3], "wb");
    if (!out) return 2;
    std::fwrite(ns.data(), sizeof(int64_t), count, out);
    std::fclose(out);
    return sink == 12345.678 ? 1 : 0;
}

//! Generates the PETSc bindings (bindgen over `wrapper.h`) and compiles the small C shim.
//!
//! PETSc is Debian's `petsc-dev` (3.18, real scalars, 32-bit indices), found with pkg-config as `PETSc`;
//! MPI's headers come from `pkg-config ompi-c`. When either is missing the build stops with one line that
//! names the set-up command.

use std::path::PathBuf;

const SETUP: &str = "run `scripts/install-deps.sh` (installs petsc-dev, libhdf5-openmpi-dev, libclang-dev, pkg-config)";

fn probe(name: &str) -> pkg_config::Library {
    match pkg_config::Config::new().cargo_metadata(true).probe(name) {
        Ok(lib) => lib,
        Err(e) => {
            let first = e.to_string().lines().next().unwrap_or_default().to_owned();
            panic!("\n\nPETSc/MPI not found through pkg-config ({name}): {first}\n=> {SETUP}\n");
        }
    }
}

fn main() {
    println!("cargo:rerun-if-changed=wrapper.h");
    println!("cargo:rerun-if-changed=src/petsc/shim.h");
    println!("cargo:rerun-if-changed=src/petsc/shim.c");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    git_describe();

    let petsc = probe("PETSc");
    let mpi = probe("ompi-c");
    // The shim's shared HDF5 files (MPI-IO): the headers of Debian's parallel HDF5, the library that
    // hdf5-metno links too.
    let hdf5 = probe("hdf5-openmpi");
    let includes: Vec<PathBuf> = petsc
        .include_paths
        .iter()
        .chain(&mpi.include_paths)
        .cloned()
        .collect();

    // The shared library directories go into the rpath so the binary runs without LD_LIBRARY_PATH.
    for dir in petsc.link_paths.iter().chain(&mpi.link_paths) {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }

    let mut shim = cc::Build::new();
    shim.file("src/petsc/shim.c").warnings(false);
    for inc in includes.iter().chain(&hdf5.include_paths) {
        shim.include(inc);
    }
    shim.compile("mpmc_petsc_shim");

    // Only the calls the safe wrappers make; the types they need follow from them.
    let functions = [
        "Petsc(Initialize|Finalize|Initialized|Finalized|ErrorMessage|PushErrorHandler|PopErrorHandler)",
        "PetscOptions(SetValue|ClearValue|HasName|GetString|GetReal|GetInt|GetBool|Left|LeftGet|LeftRestore|InsertString|Used)",
        "PetscObject(SetName|SetOptionsPrefix|GetComm|Reference)",
        "PetscLog(DefaultBegin|StageRegister|StagePush|StagePop|View|EventRegister|EventBegin|EventEnd)",
        "PetscClassIdRegister",
        "PetscViewer(ASCIIGetStdout|Destroy)",
        "Vec(Create|CreateMPI|CreateSeq|SetSizes|SetBlockSize|SetFromOptions|SetUp|Destroy|Duplicate|Copy|Set|SetValues)",
        "Vec(AssemblyBegin|AssemblyEnd|GetArray|RestoreArray|GetArrayRead|RestoreArrayRead|GetLocalSize|GetSize)",
        "Vec(GetOwnershipRange|Norm|AXPY|WAXPY|Scale|Dot|ScatterCreate|ScatterCreateToAll|ScatterBegin|ScatterEnd|ScatterDestroy)",
        "Mat(Create|SetSizes|SetType|SetBlockSize|SetFromOptions|SetUp|Destroy|SetPreallocationCOO|SetValuesCOO)",
        "Mat(SetValues|AssemblyBegin|AssemblyEnd|ZeroEntries|GetOwnershipRange|GetSize|GetLocalSize|Mult|MultAdd|SetOption|CreateVecs)",
        "Mat(SetNearNullSpace|NullSpaceCreate|NullSpaceDestroy|GetType|GetInfo|XAIJSetPreallocation|SetValuesBlocked)",
        "MatSeq(AIJ|BAIJ)(GetArray|RestoreArray)|MatSeqBAIJSetColumnIndices|MatCreateSeqAIJWithArrays|MatSeqAIJ(GetArrayRead|RestoreArrayRead)",
        "PetscContainer(Create|SetPointer|SetUserDestroy|Destroy)|PetscObjectCompose",
        "MatCreateShell|MatShell(SetOperation|GetContext)",
        "MatMPIAIJSetPreallocationCSR|MatUpdateMPIAIJWithArray|MatMPIBAIJGetSeqBAIJ|MatMPIAIJGetSeqAIJ",
        "KSP(GetIterationNumber|GetTotalIterations|GetConvergedReason|GetPC|SetType|GetType|SetTolerances|SetFromOptions)",
        "KSP(Create|Destroy|SetOperators|Solve|SetOptionsPrefix|MonitorSet)",
        "PC(SetType|GetType|FieldSplitSetIS|FactorSetMatSolverType|GetOperators|SetFailedReason|SetUp|ASMGetSubKSP|BJacobiGetSubKSP)",
        "KSPGetOperators|Mat(GetRowIJ|RestoreRowIJ|GetBlockSize)",
        "PCShell(SetContext|GetContext|SetDestroy|SetSetUp|SetApply|SetApplyRichardson|SetName)",
        "PCSORGet(Omega|Iterations|Symmetric)|PCSetUseAmat|PCGetOptionsPrefix|MatGetNonzeroState",
        "PCMG(SetLevels|GetLevels|SetGalerkin|SetInterpolation|GetSmoother)|MatSetBlockSizes",
        "SNES(Create|Destroy|SetFunction|SetJacobian|SetFromOptions|SetOptionsPrefix|Solve|GetIterationNumber)",
        "SNES(GetLinearSolveIterations|GetConvergedReason|GetKSP|SetTolerances|SetFunctionDomainError|SetType)",
        "SNES(SetJacobianDomainError|SetConvergenceHistory|GetConvergenceHistory|GetFunction|GetType|SetMaxLinearSolveFailures)",
        "SNES(GetConvergedReasonString|SetUp|GetLinearSolveFailures|GetTolerances|GetLagPreconditioner|SetLagPreconditioner)|KSPGetConvergedReasonString|MatNullSpaceCreateRigidBody",
        "SNES(SetConvergenceTest|ConvergedDefault|SetUpdate)|KSPGetTolerances",
        "IS(CreateGeneral|CreateStride|CreateBlock|Destroy|SetBlockSize)",
        "mpmc_.*",
    ];
    let mut builder = bindgen::Builder::default()
        .header("wrapper.h")
        .allowlist_function(functions.join("|"))
        .allowlist_type("(SNESConvergedReason|KSPConvergedReason|InsertMode|NormType|ScatterMode|MatOption|PetscCopyMode|PetscErrorType|MatAssemblyType|MatInfoType|MatOperation|PCFailedReason|PCRichardsonConvergedReason|MatSORType)")
        .blocklist_item("FP_.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .layout_tests(false)
        .generate_comments(false)
        .parse_callbacks(Box::new(RenameVec))
        .parse_callbacks(Box::new(bindgen::CargoCallbacks::new()));
    for inc in &includes {
        builder = builder.clang_arg(format!("-I{}", inc.display()));
    }
    let bindings = builder
        .generate()
        .unwrap_or_else(|e| panic!("\n\nbindgen failed on wrapper.h: {e}\n=> {SETUP}\n"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("OUT_DIR")).join("petsc_sys.rs");
    bindings.write_to_file(&out).expect("write bindings");
}

/// Passes `git describe` of the source tree to the crate as `MPMC_GIT_DESCRIBE` (empty outside a git
/// checkout or without git): part of the program version that every run records. The script reruns when
/// HEAD or the current branch move and when a file under `src/` changes (so `-dirty` is current for the
/// code).
fn git_describe() {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
    };
    let git_dir = git(&["rev-parse", "--git-dir"]).map(PathBuf::from);
    let common_dir = git(&["rev-parse", "--git-common-dir"]).map(PathBuf::from);
    let branch =
        git(&["rev-parse", "--symbolic-full-name", "HEAD"]).filter(|r| r.starts_with("refs/"));
    let watched = [
        git_dir.as_ref().map(|d| d.join("HEAD")),
        common_dir.as_ref().zip(branch).map(|(d, b)| d.join(b)),
        git_dir.as_ref().map(|_| PathBuf::from("src")),
    ];
    for path in watched.into_iter().flatten().filter(|p| p.exists()) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    let describe = git(&["describe", "--always", "--dirty", "--tags"]).unwrap_or_default();
    println!("cargo:rustc-env=MPMC_GIT_DESCRIBE={describe}");
}

/// PETSc's `Vec` type would shadow Rust's `Vec` in the bindings module: call it `PetscVec`.
#[derive(Debug)]
struct RenameVec;

impl bindgen::callbacks::ParseCallbacks for RenameVec {
    fn item_name(&self, item: bindgen::callbacks::ItemInfo) -> Option<String> {
        (item.name == "Vec").then(|| "PetscVec".to_owned())
    }
}

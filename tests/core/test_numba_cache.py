"""The numba cache folder is named after the kernel sources: an edit of any of them gives a new folder."""
from tissuemech.numba_cache import KERNEL_SOURCE_FOLDERS, source_keyed_cache_dir


def _package(tmp_path):
    pkg = tmp_path / "pkg"
    for folder in KERNEL_SOURCE_FOLDERS:
        (pkg / folder).mkdir(parents=True)
        (pkg / folder / "a.py").write_text(f"X = '{folder}'\n")
    (pkg / "other.py").write_text("Y = 1\n")
    return pkg


def test_folder_changes_with_a_kernel_source_and_only_with_one(tmp_path):
    pkg = _package(tmp_path)
    first = source_keyed_cache_dir(tmp_path / "cache", pkg)
    assert first.parent == tmp_path / "cache" and first.name.startswith("src-") and len(first.name) == 20
    assert source_keyed_cache_dir(tmp_path / "cache", pkg) == first  # deterministic
    (pkg / "other.py").write_text("Y = 2\n")  # not compiled into the kernels
    assert source_keyed_cache_dir(tmp_path / "cache", pkg) == first
    (pkg / "models" / "a.py").write_text("X = 'changed law'\n")  # a law the kernels inline
    changed = source_keyed_cache_dir(tmp_path / "cache", pkg)
    assert changed != first
    (pkg / "models" / "a.py").rename(pkg / "models" / "b.py")  # same bytes, another module
    assert source_keyed_cache_dir(tmp_path / "cache", pkg) not in (first, changed)


def test_the_installed_package_has_its_kernel_sources():
    from pathlib import Path

    import tissuemech

    package = Path(tissuemech.__file__).parent
    assert all(any((package / f).glob("*.py")) for f in KERNEL_SOURCE_FOLDERS)

"""An import-linter contract type written as an allow-list (pyproject.toml's ``contract_types``).

import-linter's own types forbid named modules; a renderer's rule is the other way round: of the package it
may import only what is listed (the renderer API, the scene model, its toolkit), so a module added to the
package later is out of bounds for renderers without anyone having to add it to a list.
"""

from __future__ import annotations

from grimp import ImportGraph
from importlinter.application import output
from importlinter.domain import fields
from importlinter.domain.contract import Contract, ContractCheck


def _within(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


class AllowedImportsContract(Contract):
    """Modules under ``source_modules`` import, of the modules under ``within``, only those under
    ``allowed_modules`` (or under ``source_modules`` themselves). Direct imports are checked: an allowed
    module may import what it likes, as the API does."""

    type_name = "allowed_imports"

    source_modules = fields.ListField(subfield=fields.ModuleField())
    allowed_modules = fields.ListField(subfield=fields.ModuleField())
    within = fields.ModuleField()

    def check(self, graph: ImportGraph, verbose: bool) -> ContractCheck:
        sources = [m.name for m in self.source_modules]  # type: ignore[attr-defined]
        allowed = sources + [m.name for m in self.allowed_modules]  # type: ignore[attr-defined]
        within = self.within.name  # type: ignore[attr-defined]
        illegal = []
        for source in sources:
            for importer in sorted({source} | graph.find_descendants(source)):
                for imported in sorted(graph.find_modules_directly_imported_by(importer)):
                    if _within(imported, [within]) and not _within(imported, allowed):
                        lines = graph.get_import_details(importer=importer, imported=imported)
                        illegal.append((importer, imported, [d["line_number"] for d in lines]))
        return ContractCheck(kept=not illegal, metadata={"illegal": illegal})

    def render_broken_contract(self, check: ContractCheck) -> None:
        for importer, imported, lines in check.metadata["illegal"]:
            where = ", ".join(f"l.{n}" for n in lines)
            output.print_error(f"{importer} -> {imported} ({where}): not in allowed_modules", bold=False)
        output.new_line()
